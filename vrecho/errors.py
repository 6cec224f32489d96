"""The one exception type for bad input, so callers and the CLI can answer it in one line."""


class VrechoError(ValueError):
    """Bad input or an impossible request; the message names the offending field and value."""
