"""The discrepancy workflow: where a model and the rig disagree, which effect is missing
(effects/: one module per effect), how much adding it closes the gap."""
