"""The ``crowd`` program (``crowd_addon.cli.console``): how it ends when it is stopped."""

import pytest


def test_a_stop_that_broke_a_lock_on_its_way_still_ends_as_a_stop(monkeypatch, capsys):
    """Ctrl-C landing inside a lock's wait (the PNG encoder's future) can break the
    lock, whose RuntimeError then replaces the KeyboardInterrupt: seen once in a full
    run, the command ended with a traceback and exit 1 instead of 130."""
    import signal
    import sys

    from crowd_addon import cli

    def stopped_in_a_wait(argv):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise RuntimeError("cannot release un-acquired lock")
    monkeypatch.setattr(cli, "main", stopped_in_a_wait)
    monkeypatch.delitem(sys.modules, "bpy", raising=False)     # console would os._exit
    before = signal.getsignal(signal.SIGTERM)
    try:
        assert cli.console(["preview", "--out", "x"]) == 130
    finally:
        signal.signal(signal.SIGTERM, before)
    assert capsys.readouterr().err.strip() == (
        "crowd preview: interrupted; earlier outputs are as they were")

    def failed(argv):
        raise RuntimeError("a bug")
    monkeypatch.setattr(cli, "main", failed)
    try:
        with pytest.raises(RuntimeError, match="a bug"):
            cli.console(["preview"])
    finally:
        signal.signal(signal.SIGTERM, before)
