"""Errors a user can act on."""


class SceneError(ValueError):
    """Invalid scene or input: the message names the key and the allowed range, on one line."""
