"""Nonlinear frequency response of an identified model (harmonic balance with continuation, stability,
folds, jumps, backbone) and its measured counterpart from sweep recordings. docs/frf.md."""
from .backbone import backbone
from .response import FrequencyResponse, frequency_response, natural_frequency_hz

__all__ = ["FrequencyResponse", "backbone", "frequency_response", "natural_frequency_hz"]
