"""Ctrl-C / SIGTERM held while ``ffls.errors`` renames outputs or restores state
(``run_uninterrupted``, ``atomic_outputs``, ``atomic_folder``): also when the kernel gives the signal
to another thread (docs/reliability.md)."""
import signal
import threading
import time

import pytest

from ffls.errors import run_uninterrupted


def _held(send):
    """The calls of a resumable step that sends itself a signal (``send``) once, mid-way."""
    calls = []

    def step():
        calls.append("start")
        if len(calls) == 1:
            send()
            time.sleep(0.05)  # (Python runs a pending handler at the next bytecode after this)
            sum(range(1000))
        calls.append("end")

    with pytest.raises(KeyboardInterrupt):
        run_uninterrupted(step)
    return calls


def test_a_ctrl_c_given_to_another_thread_waits_for_the_held_step():
    """The signal mask is per thread: a Ctrl-C the kernel gives to another thread (OpenCV's, Dask's)
    is run by Python's handler in the main thread at its next bytecode. Before, it raised in the middle
    of the held step (calls: start, start, end); now it is recorded and raised when the step ends."""
    done = threading.Event()
    other = threading.Thread(target=done.wait)
    other.start()
    try:
        calls = _held(lambda: signal.pthread_kill(other.ident, signal.SIGINT))
    finally:
        done.set()
        other.join()
    assert calls[:2] == ["start", "end"], calls
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_to_this_thread_waits_for_the_held_step():
    calls = _held(lambda: signal.pthread_kill(threading.get_ident(), signal.SIGINT))
    assert calls[:2] == ["start", "end"], calls
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
