"""How calls behave as Python code: errors as exceptions with mdtf's
messages, the GIL released while Rust runs, Ctrl-C honoured, threads."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import mdtf


def cli_error(mdtf_bin: Path, *args: str | os.PathLike[str]) -> str:
    """The message the mdtf command prints for a failing call (its stderr without 'error: ')."""
    r = subprocess.run([str(mdtf_bin), *map(str, args), "-q"], capture_output=True, text=True)
    assert r.returncode != 0, "the command was expected to fail"
    return r.stderr.strip().removeprefix("error: ")


def test_stage_errors_are_raised_with_the_commands_messages(mdtf_bin: Path, pipelines: Path, tmp_path: Path) -> None:
    pipeline = pipelines / "distance-tf.toml"
    for key, value, kind in [
        ("boundary.tolerance", -1, mdtf.MdtfError),
        ("derive.kernel", "bogus", ValueError),
        ("input.size", 4, mdtf.MdtfError),
    ]:
        expected = cli_error(mdtf_bin, "run", pipeline, "--set", f"{key}={value}", "-o", tmp_path / "cli")
        with pytest.raises(kind) as e:
            mdtf.run(pipeline, tmp_path / "py", settings={key: value})
        assert str(e.value) == expected
        assert not (tmp_path / "py").exists() and not (tmp_path / "cli").exists()
    with pytest.raises(mdtf.MdtfError, match=r"^bilateral\.sigma_d must be a positive number, got -1$"):
        mdtf.bilateral(np.zeros((8, 8, 8), np.float32), sigma_d=-1)
    with pytest.raises(ValueError, match="unknown item 'bogus'"):
        mdtf.derive(np.zeros((8, 8, 8), np.float32), items=["bogus"])
    with pytest.raises(ValueError, match="3-D"):
        mdtf.derive(np.zeros((8, 8), np.float32))
    with pytest.raises(mdtf.MdtfError, match="no-such.nii"):
        mdtf.read(tmp_path / "no-such.nii")


def test_the_gil_is_released_during_a_call() -> None:
    rng = np.random.default_rng(1)
    data = rng.normal(size=(96, 96, 96)).astype(np.float32)
    ticks: list[float] = []
    stop = threading.Event()

    def count() -> None:
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.05)
    # calls are repeated until they add up to long enough to tell, however fast this machine is
    calls: list[tuple[float, float]] = []
    while sum(end - start for start, end in calls) < 0.5:
        start = time.monotonic()
        mdtf.bilateral(data, sigma_d=2.0)
        calls.append((start, time.monotonic()))
    stop.set()
    t.join()
    during = 0
    longest = 0.0
    for start, end in calls:
        inside = [x for x in ticks if start <= x <= end]
        during += len(inside)
        longest = max(longest, float(np.diff([start, *inside, end]).max()))
    # a held GIL gives no tick inside any call and a gap as long as the call (0.5 s at least
    # in all); a released one ticks every millisecond, with gaps only where a loaded machine
    # leaves the thread unscheduled
    assert during > 80 and longest < 0.3, f"{during} ticks in {len(calls)} calls, longest gap {longest:.3f} s"


# Python's own Ctrl-C handler, even when started from a background job that ignores SIGINT
SCRIPT = """
import signal, sys, time, mdtf
signal.signal(signal.SIGINT, signal.default_int_handler)
print("started", flush=True)
try:
    mdtf.run(sys.argv[1], sys.argv[2], input__size=384, preview=False, slab_planes=4)
    print("finished", flush=True)
except KeyboardInterrupt:
    print("interrupted", time.monotonic(), flush=True)
"""


def test_ctrl_c_during_a_run_raises_keyboard_interrupt_within_a_second(pipelines: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    child = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(pipelines / "distance-tf.toml"), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "started"
    # the signal comes once the run is going slab by slab (its channel store holds the value:
    # the phantom is made in one piece before); a 384^3 slab run then takes several seconds
    # more on any machine, so it is still running
    deadline = time.monotonic() + 120
    while not list(tmp_path.rglob("v.f32")) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert list(tmp_path.rglob("v.f32")), "the run began its slabs"
    time.sleep(0.2)
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    stdout, stderr = child.communicate(timeout=60)
    words = stdout.split()
    assert words and words[0] == "interrupted", f"stdout {stdout!r}, stderr {stderr!r}"
    assert float(words[1]) - sent < 1.0, f"KeyboardInterrupt {float(words[1]) - sent:.2f} s after the signal"
    assert os.listdir(tmp_path) == [], "no output and no partial folder"


def test_results_do_not_depend_on_the_thread_count() -> None:
    rng = np.random.default_rng(3)
    data = rng.normal(size=(20, 24, 28)).astype(np.float32).cumsum(axis=0)
    try:
        mdtf.set_threads(1)
        assert mdtf.threads() == 1
        one = mdtf.derive(data, (1.0, 0.5, 2.0), items=["g", "f2"])
        mdtf.set_threads(2)
        assert mdtf.threads() == 2
        two = mdtf.derive(data, (1.0, 0.5, 2.0), items=["g", "f2"])
    finally:
        mdtf.set_threads(0)
    for k in one:
        np.testing.assert_array_equal(one[k], two[k])
