"""MATLAB .mat files (v4 to v7; v7.3 is HDF5 and refused with a hint): one vector per variable."""
from identify.data.recording import MAT_SUFFIXES, read_mat

from . import FileFormat

FORMAT = FileFormat("MAT", MAT_SUFFIXES, channels=lambda path, wanted: read_mat(path), noun="variable")
