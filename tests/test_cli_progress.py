"""What a CI log sees: a piped ``wrinklepipe convert`` of the 1024² demo writes one plain line
per stage as the stage starts and as it ends, at once (read here from the pipe as the run goes),
never cut to a terminal's width; Ctrl-C and SIGTERM end a run with 130 and 143 and leave nothing
behind. The console script runs as a CI runner starts it: a process with its stderr on a pipe.
The 2 s for the first line are an idle machine's: the time is divided by how much slower a
process runs now (a child spinning on the CPU measures it), as the suite's other worker and
other jobs share the cores."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from wrinklepipe.demo.source import demo_source_dir

pytestmark = pytest.mark.slow

SCRIPT = Path(sys.executable).with_name("wrinklepipe")
LINE = re.compile(r"^\s*(\d+\.\d) s  (.*)$")
#: convert's stages, in order (wrinklepipe/jobs/convert.py)
STAGES = [
    "reading inputs",
    "evaluating drivers",
    "choosing sizes, scale and formats by fidelity",
    "encoding the maps and packing the masks",
    "compressing and building the files",
    "writing the output folder",
    "validating",
]


def _cpu_seconds(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far (``/proc/PID/stat``); nan
    once it has ended."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Reader:
    """Reads a pipe line by line in a thread, noting when each line arrived."""

    def __init__(self, stream, t0: float, pid: int = 0) -> None:
        self.lines: list[tuple[float, str]] = []
        self.cpu: list[float] = []  # the child's CPU seconds when each line arrived
        self.t0 = t0
        self.pid = pid
        self._thread = threading.Thread(target=self._run, args=(stream,), daemon=True)
        self._thread.start()

    def _run(self, stream) -> None:
        for raw in stream:
            self.lines.append((time.monotonic() - self.t0, raw.rstrip("\n")))
            self.cpu.append(_cpu_seconds(self.pid))

    def cpu_at(self, text: str) -> float:
        """The child's CPU seconds (user + system) when the first line holding ``text`` came."""
        return next(c for (_, line), c in zip(self.lines, self.cpu) if text in line)

    def wait_for(self, text: str, timeout: float = 300) -> float:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for t, line in list(self.lines):
                if text in line:
                    return t
            time.sleep(0.02)
        pytest.fail(f"no line with {text!r} in {timeout} s:\n" + self.text())

    def join(self) -> None:
        self._thread.join(timeout=60)

    def text(self) -> str:
        return "\n".join(line for _, line in self.lines)


@pytest.fixture(scope="module")
def manifest() -> Path:
    """The 1024² demo (the 2048² one took ~3x as long for the same lines): its longest stages,
    compressing and validating (6.5 and 8.9 s at load 3), outlast the 2.5 s by which a line may
    lag its stage, so a start line held back until its stage ends still fails the test below."""
    return demo_source_dir(1024)


def _start(manifest: Path, out: Path) -> tuple[subprocess.Popen, Reader, float]:
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    # A test run started in the background of a shell (`pytest ... &`) has SIGINT ignored, and
    # an ignored signal stays ignored in a child: the child gets the default disposition, as a
    # convert started from a terminal has (a Python handler here becomes the default there).
    ignored = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        t0 = time.monotonic()
        proc = subprocess.Popen(
            [str(SCRIPT), "convert", str(manifest), "-o", str(out)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
    finally:
        signal.signal(signal.SIGINT, ignored)
    return proc, Reader(proc.stderr, t0, proc.pid), t0


def test_piped_convert_prints_each_stage_as_it_runs(manifest: Path, tmp_path: Path) -> None:
    out = tmp_path / ("a-long-output-folder-name-" * 4 + "end")  # the summary line passes 120
    proc, reader, t0 = _start(manifest, out)
    first = reader.wait_for("reading inputs")
    assert proc.wait(timeout=900) == 0, reader.text()
    reader.join()
    ended = time.monotonic() - t0
    assert proc.stdout.read() == ""  # progress is never on stdout
    # 2 s on an idle machine, where the process has a core to itself: counted in the CPU
    # seconds it had used when the line came (a busy machine, the suite's other worker or other
    # jobs, stretches the wall clock, not the CPU the start needs)
    cpu = reader.cpu_at("reading inputs")
    assert cpu < 2.0, f"the first stage line came after {cpu:.2f} s of CPU ({first:.2f} s wall)"
    progress = [(t, LINE.match(line)) for t, line in reader.lines if LINE.match(line)]
    said = [m.group(2) for _, m in progress]
    for stage in STAGES:
        start = said.index(stage)
        assert re.fullmatch(rf"{re.escape(stage)}: done in \d+\.\d s", said[start + 1]), said
    # each line arrived when its stage started or ended, not all at the end: the lines' own
    # clocks and their arrival times agree, and the run's stages spread over its time
    for t, m in progress:
        assert abs(float(m.group(1)) - t) < 2.5, (t, m.group(0))
    arrivals = [t for t, _ in progress]
    assert arrivals == sorted(arrivals)
    assert arrivals[-1] - arrivals[0] > 0.5 * (ended - arrivals[0])
    # no line cut: the summary names the folder whole, on one line
    wrote = [line for _, line in reader.lines if line.startswith("wrote ")]
    assert wrote and str(out) in wrote[0] and wrote[0].endswith("vertices"), reader.text()
    assert any(line.startswith("validation: 0 errors, ") for _, line in reader.lines)


@pytest.mark.parametrize(
    ("sig", "code", "during"),
    [
        (signal.SIGINT, 130, "choosing sizes, scale and formats by fidelity"),
        (signal.SIGTERM, 143, "reading inputs"),
    ],
)
def test_a_signal_ends_convert_with_its_code_and_nothing_partial(
    manifest: Path, tmp_path: Path, sig: int, code: int, during: str
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    proc, reader, _ = _start(manifest, work / "out")
    reader.wait_for(during)
    time.sleep(0.3)
    proc.send_signal(sig)
    assert proc.wait(timeout=120) == code, reader.text()
    reader.join()
    assert f"interrupted ({signal.Signals(sig).name})" in reader.text()
    assert sorted(os.listdir(work)) == []  # no output, no staging folder, no lock file
