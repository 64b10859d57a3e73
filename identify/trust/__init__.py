"""What a fitted model can be trusted for: standard errors, inclusion probabilities, the noise's
share of the variance."""
