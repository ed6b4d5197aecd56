"""How a stop is raised and held back (emml/envs/stops.py, issue 85): Ctrl-C inside `stop_after` waits for the block
to end like SIGTERM (it used to cut MLflow's metric insert in the middle), comes out as KeyboardInterrupt (what the
stop line calls 'Ctrl-C'), and is remembered by `stop_requested`; a SIGINT inherited ignored stays ignored."""

from __future__ import annotations

import signal
import threading

import pytest

from emml.envs import stops


def _to_main_thread(sig) -> None:
    """The signal to this process's main thread, delivered before the call returns (`os.kill` to the process may
    reach another thread first, and the main thread see it bytecodes later on a busy machine)."""
    signal.pthread_kill(threading.main_thread().ident, sig)


SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@pytest.fixture
def handlers():
    saved = {sig: signal.getsignal(sig) for sig in SIGNALS}
    # a terminal's process: a suite started in the background without job control (`nohup make test &`) inherits
    # SIGINT ignored, which install_signal_handlers rightly keeps (tested below): these tests would then fail
    signal.signal(signal.SIGINT, signal.default_int_handler)
    stops.install_signal_handlers()
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)
    stops.reset_stop()


@pytest.mark.parametrize(("sig", "raised"), [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, SystemExit)])
def test_a_stop_inside_stop_after_comes_when_the_block_ends(handlers, sig, raised):
    finished = []
    assert stops.stop_requested() is None
    with pytest.raises(raised) as stop:
        with stops.stop_after():
            with stops.stop_after():  # nested: the outermost block decides
                _to_main_thread(sig)
                finished.append("inner")
                assert stops.stop_requested() is not None  # noted at once, raised later
            finished.append("outer")
    assert finished == ["inner", "outer"]
    if raised is SystemExit:
        assert stop.value.code == 128 + signal.SIGTERM


def test_outside_a_block_ctrl_c_stops_at_once_and_the_first_signal_names_the_stop(handlers):
    with pytest.raises(KeyboardInterrupt):
        _to_main_thread(signal.SIGINT)
        pytest.fail("never reached")
    with pytest.raises(SystemExit) as stop:  # SIGTERM first, then Ctrl-C: 'signal SIGTERM' it was
        with stops.stop_after():
            _to_main_thread(signal.SIGTERM)
            _to_main_thread(signal.SIGINT)
    assert stop.value.code == 128 + signal.SIGTERM


def test_a_sigint_inherited_ignored_stays_ignored():
    saved = {sig: signal.getsignal(sig) for sig in SIGNALS}
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a launcher's child (emml/experiments/pool.py)
        stops.install_signal_handlers()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) is stops._on_signal
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
