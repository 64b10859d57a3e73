"""The sensor-noise model: the noise floor from Welch spectra, and the chain's image of white noise."""
