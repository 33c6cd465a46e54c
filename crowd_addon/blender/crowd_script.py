"""The scene's crowd script (``scene.crowd.show.script``) and whether it may run.

A crowd script is a text in the .blend whose ``register(crowd)`` is run on every
crowd built from the scene (:func:`run_script`). Scripts in .blend files run only
where trusted (:func:`script_trusted`): for one call (``--trust-scripts``, a shot's
``trust_scripts``), by Blender's *Auto Run Python Scripts* preference, or by the
panel's *Trust Script* for exactly this text of this file in this process
(:func:`trust_script`). A command refuses a scene whose script would not run
(:func:`check_script`); a script that fails raises a CrowdError naming the text and
the line.
"""

from __future__ import annotations

import hashlib
import os

from ..core.base.errors import CrowdError, ScriptNotTrusted

__all__ = ["run_script", "script_key", "script_trusted", "trust_script",
           "forget_trusted_scripts", "script_refusal", "check_script"]

#: crowd scripts trusted in this Blender process by the panel's *Trust Script*
#: (:func:`trust_script`): keys ``(the .blend's absolute path, the text's name, the
#: sha256 of its content)``. Never saved (trust is the person's, not the file's), never
#: a switch for every file: another file, or the same text changed, is not in it. The
#: command line's ``--trust-scripts`` and a shot's ``trust_scripts`` add nothing here:
#: they are an argument of the one call they are given to (``run_script(trusted=)``).
_TRUSTED: set = set()


def _key(text, source: str) -> tuple:
    import bpy
    path = bpy.data.filepath
    return (os.path.abspath(path) if path else "", text.name_full,
            hashlib.sha256(source.encode("utf-8")).hexdigest())


def script_key(text) -> tuple:
    """What trusting the crowd script ``text`` trusts: ``(the open .blend's absolute
    path ("" while unsaved), the text's name, the sha256 hex digest of its content)``."""
    return _key(text, text.as_string())


def trust_script(text) -> tuple:
    """Trust the crowd script ``text`` of the open .blend for this Blender process (the
    panel's *Trust Script*): exactly this file's text with this content, nothing else.
    Returns its :func:`script_key`."""
    key = script_key(text)
    _TRUSTED.add(key)
    return key


def forget_trusted_scripts(unsaved_only: bool = False):
    """Forget the scripts :func:`trust_script` trusted (``unsaved_only``: those of an
    unsaved file, whose key has no path: done whenever a file is loaded)."""
    if unsaved_only:
        _TRUSTED.difference_update([k for k in _TRUSTED if not k[0]])
    else:
        _TRUSTED.clear()


def _auto_run() -> bool:
    import bpy
    return bool(bpy.context.preferences.filepaths.use_scripts_auto_execute
                and not bpy.app.autoexec_fail)


def script_trusted(text, trusted: bool = False) -> bool:
    """Whether the crowd script ``text`` of the open .blend may run: ``trusted`` (given
    for this one call: ``--trust-scripts``, a shot's ``trust_scripts``), Blender's *Auto
    Run Python Scripts* preference (and the file was not blocked by it), or this very
    text of this file trusted in this process (:func:`trust_script`)."""
    return _trusted(text, text.as_string(), trusted)


def _trusted(text, source: str, trusted: bool) -> bool:
    return bool(trusted) or _auto_run() or _key(text, source) in _TRUSTED


def _untrusted(text) -> str:
    return (f"crowd script {text.name!r} did not run: scripts in .blend files are not "
            "trusted here (enable Auto Run Python Scripts, press Trust Script in the "
            "Show panel, or pass --trust-scripts)")


def script_refusal(scene, trusted: bool = False) -> str:
    """Why the scene's crowd script would not run here (:func:`script_trusted`;
    ``trusted`` as :func:`run_script`), or "" when it would run or there is none."""
    text = scene.crowd.show.script
    if text is None or _trusted(text, text.as_string(), trusted):
        return ""
    return _untrusted(text)


def check_script(scene, trusted: bool = False, ignore: bool = False) -> None:
    """What a command does before it builds a crowd: a scene whose crowd script would
    not run here is refused with :class:`~crowd_addon.core.base.errors.ScriptNotTrusted`
    (the command's exit code 3), since the command would otherwise play a show other
    than the file's; ``ignore`` (``--ignore-scripts``) goes on without the script."""
    reason = "" if ignore else script_refusal(scene, trusted)
    if reason:
        raise ScriptNotTrusted(f"{reason}; nothing was done (pass --ignore-scripts to go "
                               "on without the script)")


def run_script(scene, crowd, trusted: bool = False, ignore: bool = False) -> str:
    """Run the scene's crowd script on ``crowd`` (its ``register(crowd)``); returns ""
    when it ran or there is none, else why it did not run (not trusted:
    :func:`script_trusted`; ``trusted`` holds for this call only; ``ignore``: left out
    whether trusted or not, ``--ignore-scripts``). A script that fails raises a
    CrowdError naming the text and the line."""
    text = scene.crowd.show.script
    if text is None:
        return ""
    if ignore:
        return f"crowd script {text.name!r} left out (--ignore-scripts)"
    source = text.as_string()              # what is checked is what runs
    if not _trusted(text, source, trusted):
        return _untrusted(text)
    import traceback
    import types
    module = types.ModuleType(f"crowd_script_{text.name}")
    module.__file__ = text.name
    try:
        exec(compile(source, text.name, "exec"), module.__dict__)
        register = getattr(module, "register", None)
        if not callable(register):
            raise CrowdError(f"crowd script {text.name!r} defines no register(crowd)")
        register(crowd)
    except CrowdError:
        raise
    except Exception as e:  # noqa: BLE001 - any error of user code is named
        line = next((f.lineno for f in reversed(traceback.extract_tb(e.__traceback__))
                     if f.filename == text.name), None)
        where = f" at line {line}" if line else ""
        raise CrowdError(f"crowd script {text.name!r} failed{where}: "
                         f"{type(e).__name__}: {e}") from None
    return ""
