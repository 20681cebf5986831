"""Long calls release the GIL and stop on Ctrl-C."""

import _thread
import glob
import os
import signal
import threading
import time

import pytest

import plantc
from conftest import data_dir, model_path

PEND = model_path("rotary_pendulum.plant")
TWO = sorted(glob.glob(os.path.join(data_dir("demo_two_effects"), "*.csv")))


def workers():
    """This process's threads named `plantc-worker` (Linux)."""
    n = 0
    for t in glob.glob("/proc/self/task/*/comm"):
        try:
            with open(t) as f:
                n += f.read().strip() == "plantc-worker"
        except OSError:
            pass
    return n


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="needs Linux /proc")
def test_keyboard_interrupt_stops_identify(tmp_path):
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(1)
            time.sleep(0.01)

    # Ctrl-C as at a terminal: Python's own SIGINT handler, whatever the
    # process inherited (a background job of a non-interactive shell starts
    # with SIGINT ignored, and then `interrupt_main` does nothing)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    counter = threading.Thread(target=count)
    counter.start()
    timer = threading.Timer(1.0, _thread.interrupt_main)
    timer.start()
    out = tmp_path / "out"
    try:
        with pytest.raises(KeyboardInterrupt):
            plantc.Model.load(PEND).identify(TWO, out=out)
    finally:
        stop.set()
        counter.join()
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    # the GIL was released: the other Python thread ran during the call
    assert len(ticks) > 20
    # the worker unwinds at its next progress report (every fit iteration;
    # the diagnosis' screening of candidates reports nothing, so that can
    # take a while): wait for it to go. Had it finished instead, the story
    # would have written its directory; unwound, it leaves nothing.
    for _ in range(6000):
        if workers() == 0:
            break
        time.sleep(0.05)
    assert workers() == 0
    assert not out.exists() or not any(out.iterdir())
    # and the module still works
    assert plantc.Model.load(PEND).linearize().A.shape == (4, 4)
