"""Exceptions that the command line turns into one clear line and a non-zero exit."""


class GritsError(Exception):
    """Base class for every error a user can cause and fix (bad input, bad config, missing files)."""


class ConfigError(GritsError):
    """A config file or value is invalid; the message names the key and the value."""


class InputError(GritsError):
    """A command-line argument or input file is invalid (wrong shape, NaN, unknown name)."""


class StorageError(GritsError):
    """An output location cannot be written, or a stored file is missing or corrupted."""


class JobError(GritsError):
    """A job ran but produced nothing: every unit of work it tried failed. The message names how
    many, the first error, and where the tracebacks are."""
