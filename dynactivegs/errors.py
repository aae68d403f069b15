"""User-facing errors.

Every problem a user can cause (a missing file, a malformed mesh, a bad config value)
is raised as a :class:`DagsError` whose message is one line naming the problem and the
fix. The command-line entry points print that line and exit with status 2 instead of
showing a traceback.
"""

from __future__ import annotations


class DagsError(Exception):
    """A problem with the user's input, with a one-line message saying how to fix it."""

    def __init__(self, message: str) -> None:
        assert "\n" not in message, "DagsError messages are one line"
        super().__init__(message)


class SceneError(DagsError):
    """A scene name or scene file that cannot be used."""


class ConfigError(DagsError):
    """A config value outside its allowed range or of the wrong kind."""


def check_config(cond: bool, name: str, value: object, allowed: str) -> None:
    """Raise :class:`ConfigError` ``bad config value NAME=VALUE: must be ALLOWED`` unless ``cond``."""
    if not cond:
        raise ConfigError(f"bad config value {name}={value!r}: must be {allowed}")
