"""Errors the user sees as one line: what was wrong, with which value, and what to do."""


class PlenocliError(Exception):
    """Base class; the message is shown to the user as it is (no traceback unless --debug)."""


class InputError(PlenocliError):
    """An input file is missing, unreadable, of the wrong kind, or does not match another input."""


class ConfigError(PlenocliError):
    """A pipeline configuration or a parameter value is invalid."""


class CalibrationError(PlenocliError):
    """A calibration (lens grid, white image) cannot be estimated or does not fit the data."""
