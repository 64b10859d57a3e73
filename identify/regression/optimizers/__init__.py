"""Sparse regression along a path: each optimizer is one small class on the shared scaffolding."""
from .admm import ADMMLasso
from .base import PathOptimizer, SparsePath
from .stlsq import STLSQ

OPTIMIZERS = {"admm": ADMMLasso, "stlsq": STLSQ}

__all__ = ["ADMMLasso", "STLSQ", "PathOptimizer", "SparsePath", "OPTIMIZERS"]
