"""The one exception type of the crowd core."""


class CrowdError(ValueError):
    """Bad input to the crowd: the message names the bone, clip, stream, agent or field.

    Raised before anything is changed, so the crowd stays as it was.
    """
