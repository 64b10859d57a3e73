"""Build the one compiled piece: the fixed-step free-run simulation kernel.

Everything else is pure Python on numpy/scipy. Time stepping is inherently sequential, so numpy
cannot vectorise it, and a Python loop is ~100x slower than the target (see docs/identification.md).
The kernel uses only the CPython C API and the buffer protocol (no numpy headers at build time).
"""
from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension("identify._simkernel", sources=["identify/_simkernel.c"], extra_compile_args=["-O3"]),
    ]
)
