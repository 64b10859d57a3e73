"""Build the two compiled pieces: the fixed-step free-run simulation kernel, and the rows of the noise
share of the variance (identify/_polyrows.c).

Everything else is pure Python on numpy/scipy. Time stepping is inherently sequential, so numpy
cannot vectorise it, and a Python loop is ~100x slower than the target (see docs/identification.md).
The noise share's rows are polynomials of the signals that numpy made in many whole-array passes.
Both use only the CPython C API and the buffer protocol (no numpy headers at build time).
"""
from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension("identify._simkernel", sources=["identify/_simkernel.c"], depends=["identify/_simkernel_run.h"],
                  extra_compile_args=["-O3"]),
        Extension("identify._polyrows", sources=["identify/_polyrows.c"], extra_compile_args=["-O3"]),
    ]
)
