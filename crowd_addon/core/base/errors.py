"""The one exception type of the crowd core."""


class CrowdError(ValueError):
    """Bad input to the crowd: the message names the bone, clip, stream, agent or field.

    Raised before anything is changed, so the crowd stays as it was.
    """


class ScriptNotTrusted(CrowdError):
    """A .blend's crowd script would change the show but is not trusted where the
    command runs: the command stops (exit code 3) rather than go on with another show,
    unless told to go on without the script (``--ignore-scripts``). The message says
    which script and how to trust it."""

    exit_code = 3
