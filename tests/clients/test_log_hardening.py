"""Bad logs (issue 32, finding 8): every log tool refuses them at once, one line, exit code 2.

Each bad log is built here from a committed fixture: a flipped byte in a chunk's
zstd data, a corrupt chunk CRC or zstd frame, a chunk cut out, a record length
that runs past the end of a closed file, zstd bombs (a chunk declaring more than
a reader takes, chunks declaring more than the file's size allows, a chunk whose
data decompresses to more than it declares), a FIFO and a directory. A log
without a command to compare is no pass either.
"""

import os
import struct
import subprocess
import sys
import zlib
from collections.abc import Callable
from pathlib import Path

import pytest
import zstandard

from clients.log_info import format_summary, summarize_log
from clients.replay import ReplayError, load_replay
from clients.server_process import ServerProcess
from controller_server.cli import main
from protocol import recording
from protocol.messages import Hello
from protocol.recording import (
    MAX_CHUNK_BYTES,
    MAX_EXPANSION,
    SMALL_LOG_BYTES,
    BadLog,
    Recorder,
    read_log,
)
from tests.protocol.samples import sample_messages

ROOT = Path(__file__).resolve().parents[2]
FIXTURE = ROOT / "tests" / "fixtures" / "replay_momentum_push.mcap"
CHUNK, FOOTER = 0x06, 0x02
CHUNK_DATA_AT = 9 + 8 + 8 + 8 + 4 + 4 + 4 + 8  # opcode, length, times, size, CRC, "zstd", length
FIRST_STATES_CHUNK = 2  # chunks 0 and 1 hold the hello and the welcome (flushed at once)
BOMB_BYTES = 1 << 30
TOOLS = {
    "replay": lambda log, out: ["replay", log],
    "info": lambda log, out: ["log", "info", log],
    "plot": lambda log, out: ["log", "plot", log, "--output", out],
}


def chunks(data: bytes) -> list[tuple[int, int]]:
    """``(offset, length)`` of each top-level chunk record of an MCAP file."""
    offset, found = 8, []
    while offset + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, offset)
        if opcode == CHUNK:
            found.append((offset, length))
        if opcode == FOOTER:
            break
        offset += 9 + length
    return found


def zeros_frame(size: int) -> tuple[bytes, int]:
    """A zstd frame of ``size`` zero bytes (32 kB for a GiB) and their CRC, in 1 MiB steps."""
    compressor = zstandard.ZstdCompressor(level=1).compressobj()
    block, parts, crc = bytes(1 << 20), [], 0
    for _ in range(size >> 20):
        parts.append(compressor.compress(block))
        crc = zlib.crc32(block, crc)
    parts.append(compressor.flush())
    return b"".join(parts), crc


def chunk_record(frame: bytes, declared_bytes: int, crc: int) -> bytes:
    body = struct.pack("<QQQII", 0, 0, declared_bytes, crc, 4) + b"zstd"
    body += struct.pack("<Q", len(frame)) + frame
    return struct.pack("<BQ", CHUNK, len(body)) + body


def with_chunk(data: bytes, index: int, record: bytes) -> bytes:
    """``data`` with its chunk ``index`` replaced by ``record`` (b"": cut out)."""
    offset, length = chunks(data)[index]
    return data[:offset] + record + data[offset + 9 + length :]


def flipped(data: bytes, offset: int, mask: int = 0x10) -> bytes:
    changed = bytearray(data)
    changed[offset] ^= mask
    return bytes(changed)


def flip_chunk_data(data: bytes) -> bytes:
    offset, length = chunks(data)[FIRST_STATES_CHUNK]
    return flipped(data, offset + CHUNK_DATA_AT + (length - CHUNK_DATA_AT + 9) // 2)


def corrupt_zstd_frame(data: bytes) -> bytes:
    offset, _ = chunks(data)[FIRST_STATES_CHUNK]
    return flipped(data, offset + CHUNK_DATA_AT, 0xFF)  # the frame's magic number


def corrupt_crc(data: bytes) -> bytes:
    offset, _ = chunks(data)[FIRST_STATES_CHUNK]
    return flipped(data, offset + 9 + 24, 0xFF)


def corrupt_length(data: bytes) -> bytes:
    offset, _ = chunks(data)[FIRST_STATES_CHUNK]
    return flipped(data, offset + 1 + 3, 0x01)  # 16 MiB more: past the end of the file


def cut_out_a_chunk(data: bytes) -> bytes:
    return with_chunk(data, len(chunks(data)) // 2, b"")


def cut_out_a_slice(data: bytes) -> bytes:
    middle = len(data) // 2
    return data[:middle] + data[middle + 1000 :]


def declares_a_terabyte(data: bytes) -> bytes:
    frame, crc = zeros_frame(1 << 20)
    return with_chunk(data, FIRST_STATES_CHUNK, chunk_record(frame, 1 << 40, crc))


def over_the_expansion_bound(data: bytes) -> bytes:
    """Honest chunks of 96 MiB of zeros: each below a chunk's limit, more than the file allows."""
    frame, crc = zeros_frame(96 << 20)
    return with_chunk(data, FIRST_STATES_CHUNK, chunk_record(frame, 96 << 20, crc))


def holds_more_than_it_declares(data: bytes) -> bytes:
    """A chunk declaring 1 MiB whose data is 64 MiB of zeros: decompressed no further than 1 MiB."""
    frame, crc = zeros_frame(64 << 20)
    return with_chunk(data, FIRST_STATES_CHUNK, chunk_record(frame, 1 << 20, crc))


BAD_LOGS: dict[str, Callable[[bytes], bytes]] = {
    "chunk-data-flipped": flip_chunk_data,
    "zstd-frame-corrupt": corrupt_zstd_frame,
    "chunk-crc-corrupt": corrupt_crc,
    "record-length-corrupt": corrupt_length,
    "chunk-cut-out": cut_out_a_chunk,
    "slice-cut-out": cut_out_a_slice,
    "declares-a-terabyte": declares_a_terabyte,
    "over-the-expansion-bound": over_the_expansion_bound,
    "holds-more-than-it-declares": holds_more_than_it_declares,
    "summary-flipped": lambda data: flipped(data, len(data) - 100),
    "closing-magic-flipped": lambda data: flipped(data, len(data) - 1),
}


@pytest.fixture(scope="module")
def bad_logs(tmp_path_factory) -> dict[str, Path]:
    directory = tmp_path_factory.mktemp("bad-logs")
    data = FIXTURE.read_bytes()
    paths = {}
    for name, build in BAD_LOGS.items():
        paths[name] = directory / f"{name}.mcap"
        paths[name].write_bytes(build(data))
    return paths


@pytest.fixture(scope="module")
def bombs(tmp_path_factory) -> dict[str, Path]:
    """A 1 GiB zstd bomb in a chunk (32 kB): declared honestly, and declared as 1 MiB."""
    directory = tmp_path_factory.mktemp("bombs")
    data = FIXTURE.read_bytes()
    frame, crc = zeros_frame(BOMB_BYTES)
    paths = {"honest": directory / "honest.mcap", "lying": directory / "lying.mcap"}
    paths["honest"].write_bytes(
        with_chunk(data, FIRST_STATES_CHUNK, chunk_record(frame, BOMB_BYTES, crc))
    )
    paths["lying"].write_bytes(
        with_chunk(data, FIRST_STATES_CHUNK, chunk_record(frame, 1 << 20, crc))
    )
    return paths


@pytest.fixture
def no_server(monkeypatch):
    """Fail any attempt to start `poise serve`; yields the list of attempts."""
    started: list[list[str]] = []

    def refuse(self):
        started.append(self.command)
        raise RuntimeError("a server was started for a log that cannot be replayed")

    monkeypatch.setattr(ServerProcess, "start", refuse)
    return started


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


def test_the_committed_fixtures_read_whole_with_every_check():
    """Chunk CRCs, message indexes, summary CRC and statistics of a closed log all agree."""
    for fixture in sorted(FIXTURE.parent.glob("*.mcap")):
        reader = read_log(fixture)
        assert len(list(reader)) == reader.messages_read > 100
        assert not reader.truncated


@pytest.mark.parametrize("name", list(BAD_LOGS))
def test_a_bad_log_raises_bad_log_in_one_line(bad_logs, name):
    with pytest.raises(BadLog) as caught:
        list(read_log(bad_logs[name]))
    assert "\n" not in str(caught.value) and str(bad_logs[name]) in str(caught.value)


def test_every_chunk_crc_is_checked(tmp_path):
    data = FIXTURE.read_bytes()
    path = tmp_path / "crc.mcap"
    for offset, _ in chunks(data):
        path.write_bytes(flipped(data, offset + 9 + 24, 0x01))
        with pytest.raises(BadLog, match="does not match its CRC"):
            list(read_log(path))


def test_the_bounds_are_checked_before_decompressing(monkeypatch):
    """With a reader's bounds below the fixture's, its chunks are refused, naming the bound."""
    with pytest.raises(BadLog, match=r"more than a reader takes .*zstd bomb"):
        list(read_log(FIXTURE, max_chunk_bytes=100_000))
    monkeypatch.setattr(recording, "SMALL_LOG_BYTES", 0)
    with pytest.raises(BadLog, match=r"0.5 times its size.*zstd bomb"):
        list(read_log(FIXTURE, max_expansion=0.5))
    # over-the-expansion-bound: each chunk below the limit, together above what the file allows
    assert SMALL_LOG_BYTES < 96 << 20 < MAX_CHUNK_BYTES
    assert MAX_EXPANSION * FIXTURE.stat().st_size < 96 << 20


@pytest.mark.parametrize("tool", list(TOOLS))
@pytest.mark.parametrize("name", list(BAD_LOGS))
def test_every_log_tool_refuses_a_bad_log_in_one_line_without_a_server(
    bad_logs, name, tool, tmp_path, capsys, no_server
):
    """`poise replay` (no --connect: it would start a server), `log info`, `log plot`."""
    code = main(TOOLS[tool](str(bad_logs[name]), str(tmp_path)))
    stderr = capsys.readouterr().err
    assert code == 2, stderr
    assert "not a readable Poise log" in one_line(stderr)
    assert no_server == []
    assert not list(tmp_path.glob("*.png"))


@pytest.mark.parametrize("tool", list(TOOLS))
def test_a_fifo_or_a_directory_is_refused_at_once_not_waited_on(tmp_path, tool):
    """Through the real command line: opening a FIFO for reading used to wait for a writer."""
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "FIFO"), (tmp_path, "directory")):
        result = subprocess.run(
            [sys.executable, "-m", "controller_server.cli", *TOOLS[tool](str(path), "/tmp")],
            capture_output=True,
            text=True,
            timeout=60,  # a hang fails here, in a minute at most
            stdin=subprocess.DEVNULL,
            cwd=ROOT,
        )
        assert result.returncode == 2, result.stderr
        assert kind in one_line(result.stderr) and "not a regular file" in result.stderr


def test_a_corrupt_chunk_is_no_pass_through_the_command_line(bad_logs):
    """The attack's false pass: "replay matches the recording, compared 0 commands", exit 0."""
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "controller_server.cli",
            "replay",
            str(bad_logs["chunk-data-flipped"]),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        cwd=ROOT,
    )
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "the file is corrupt" in one_line(result.stderr)
    assert "matches" not in result.stdout


PEAK_MEMORY = """
import resource, subprocess, sys
runs = [arguments.split("|") for arguments in sys.argv[1:]]
for arguments in runs:
    result = subprocess.run(
        [sys.executable, "-m", "controller_server.cli", *arguments],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )
    print(result.returncode, repr(result.stderr))
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)
"""


@pytest.mark.slow
def test_a_zstd_bomb_is_refused_without_decompressing_it(bombs, tmp_path):
    """A 1 GiB bomb peaked at 2.2 GB before its error (or ran for minutes); now the
    tools' own size (under 0.3 GB, matplotlib and all), declared honestly or not."""
    runs = [
        "|".join(TOOLS[tool](str(bombs[kind]), str(tmp_path)))
        for kind in ("honest", "lying")
        for tool in TOOLS
    ]
    measured = subprocess.run(
        [sys.executable, "-c", PEAK_MEMORY, *runs],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    *results, peak_bytes = measured.stdout.strip().splitlines()
    print(
        f"peak memory of a log tool on a {BOMB_BYTES >> 20} MiB bomb: {int(peak_bytes) >> 20} MiB"
    )
    assert len(results) == len(runs), measured.stderr
    for arguments, result in zip(runs, results, strict=True):
        code, stderr = result.split(" ", 1)
        assert code == "2", (arguments, stderr)
        stderr = eval(stderr)  # the repr printed above
        assert "zstd bomb" in one_line(stderr) or "more bytes than" in stderr, stderr
    assert int(peak_bytes) < BOMB_BYTES / 3


def handshake_only(path: Path) -> Path:
    welcome = next(m for m in sample_messages() if m.type == "welcome")
    with Recorder(path) as recorder:
        recorder.record(Hello(seq=1, model="thesis_humanoid"), "sent")
        recorder.record(welcome, "received")
    return path


def test_a_log_without_commands_is_not_a_replay_that_passes(tmp_path, capsys, no_server):
    """Replay and plot refuse it before any server starts; info says so and shows it."""
    path = handshake_only(tmp_path / "handshake.mcap")
    with pytest.raises(ReplayError, match="holds no commands to compare"):
        load_replay(path)
    assert main(["replay", str(path)]) == 2
    assert "holds no commands to compare" in one_line(capsys.readouterr().err)
    assert main(["log", "plot", str(path), "--output", str(tmp_path)]) == 2
    assert "nothing to plot" in one_line(capsys.readouterr().err)
    assert no_server == []
    assert main(["log", "info", str(path)]) == 0
    assert "`poise replay` has nothing to compare" in capsys.readouterr().out
    assert "nothing to compare" in format_summary(path, summarize_log(path))


def test_a_log_cut_before_its_first_command_is_refused_too(tmp_path, capsys, no_server):
    """A killed recorder's log replays up to the cut, unless nothing before it can be compared."""
    data = FIXTURE.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunks(data)[FIRST_STATES_CHUNK][0] + 100])
    assert main(["replay", str(cut)]) == 2
    assert "holds no commands to compare" in capsys.readouterr().err.strip().splitlines()[-1]
    assert no_server == []
    later = tmp_path / "later.mcap"
    later.write_bytes(data[: len(data) // 2])  # a prefix with commands: still replayable
    recorded = load_replay(later)
    assert recorded.truncated and recorded.comparable_commands > 0
