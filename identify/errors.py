"""Errors a user can act on. The CLI prints their message on one line and exits non-zero."""


class ShakeidError(Exception):
    """Base class of every error meant for the operator rather than a traceback."""


class RecordingError(ShakeidError):
    """A recording cannot be read or is unfit for identification (names the file and the problem)."""


class ModelError(ShakeidError):
    """A model or term specification is invalid."""


class IdentificationError(ShakeidError):
    """Identification could not produce a model (too little data, no excitation, ...)."""
