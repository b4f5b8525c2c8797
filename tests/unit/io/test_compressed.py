"""Compressed CSV logs (gzip, bzip2, xz, zstd) are read as they are decompressed, recognised by their magic bytes.

The reference is the same log uncompressed: identify's JSON must be the same figure for figure (only the note
that says it was decompressed, and the run time, differ), and ``wmrid identify log.csv.gz`` must equal
``zcat log.csv.gz | wmrid identify -``.  The compressed files are written by Python's own gzip, bz2 and lzma
modules and by zstandard (the library wmrid decompresses with), so both sides are the real formats.
"""

from __future__ import annotations

import bz2
import gzip
import json
import lzma

import numpy as np
import pytest
import zstandard

from tests.cliutil import wmrid
from wmrid.io.logs import open_log, read_log

COMPRESS = {
    "gzip": (".gz", gzip.compress),
    "bzip2": (".bz2", bz2.compress),
    "xz": (".xz", lzma.compress),
    "zstd": (".zst", lambda data: zstandard.ZstdCompressor().compress(data)),
}


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """A 3 s simulated CSV log."""
    path = tmp_path_factory.mktemp("log") / "run.csv"
    assert wmrid("simulate", "--duration", "3", "-o", str(path)).returncode == 0
    return path


def _identify(*args: str, stdin: bytes | None = None) -> dict:
    out = wmrid("identify", *args, "--format", "json", stdin=stdin)
    assert out.returncode == 0, out.stderr.decode()
    return json.loads(out.stdout)


def _same_figures(a: dict, b: dict) -> None:
    """Every estimate and every log figure equal; the notes equal but for one naming the compression."""
    assert a["parameters"] == b["parameters"]
    assert a["estimate"] == b["estimate"]
    assert a["log"]["samples"] == b["log"]["samples"]
    assert a["warnings"] == b["warnings"]
    a_notes, b_notes = ([n for n in x["log"]["notes"] if "-compressed: decompressed" not in n] for x in (a, b))
    assert a_notes == b_notes


@pytest.mark.parametrize("kind", sorted(COMPRESS))
def test_a_compressed_csv_identifies_as_the_plain_one(tmp_path, plain, kind):
    suffix, compress = COMPRESS[kind]
    path = tmp_path / f"run.csv{suffix}"
    path.write_bytes(compress(plain.read_bytes()))
    before = path.read_bytes()
    result = _identify(str(path))
    _same_figures(_identify(str(plain)), result)
    assert f"{kind}-compressed: decompressed as it was read" in result["log"]["notes"]
    assert path.read_bytes() == before  # the input is never modified


def test_the_file_equals_zcat_into_standard_input(tmp_path, plain):
    """``wmrid identify log.csv.gz`` = ``zcat log.csv.gz | wmrid identify -`` (and the gzip bytes piped in too)."""
    path = tmp_path / "run.csv.gz"
    path.write_bytes(gzip.compress(plain.read_bytes()))
    from_file = _identify(str(path))
    _same_figures(_identify("-", stdin=gzip.decompress(path.read_bytes())), from_file)
    _same_figures(_identify("-", stdin=path.read_bytes()), from_file)


def test_the_suffix_does_not_matter_and_pieces_join_to_the_whole(tmp_path, plain):
    """Magic bytes decide: a gzip stream named .txt, .dat or without suffix is read; streamed in small pieces
    (bounded memory) it gives the samples of the plain file."""
    whole = read_log(str(plain))
    for name in ("run.txt", "run.dat", "run"):
        path = tmp_path / name
        path.write_bytes(gzip.compress(plain.read_bytes()))
        stream = open_log(str(path), rows=500)
        pieces = list(stream)
        assert max(len(p) for p in pieces) == 500
        assert np.array_equal(np.concatenate([p.t for p in pieces]), whole.t)
        assert np.array_equal(np.concatenate([p.eta for p in pieces]), whole.eta)
        assert np.array_equal(np.concatenate([p.tau for p in pieces]), whole.tau)


def test_a_bad_row_is_named_by_its_line_in_the_decompressed_text(tmp_path, plain):
    lines = plain.read_text().splitlines(keepends=True)
    lines[100] = lines[100].replace(",", ",oops", 1)
    path = tmp_path / "bad.csv.xz"
    path.write_bytes(lzma.compress("".join(lines).encode()))
    out = wmrid("identify", str(path))
    assert out.returncode == 2
    err = out.stderr.decode()
    assert "line 101" in err
    assert "not a number" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("kind", ["gzip", "xz", "zstd", "bzip2"])
def test_a_damaged_or_cut_stream_is_named_with_the_check(tmp_path, plain, kind):
    suffix, compress = COMPRESS[kind]
    data = compress(plain.read_bytes())
    path = tmp_path / f"cut.csv{suffix}"
    path.write_bytes(data[: len(data) // 2])
    out = wmrid("identify", str(path))
    assert out.returncode == 2
    err = out.stderr.decode().strip()
    assert len(err.splitlines()) == 1, err
    assert str(path) in err
    assert f"its {kind} stream is damaged or cut short" in err


def test_other_formats_inside_a_compressed_file_are_refused_with_the_command(tmp_path, plain):
    parquet = tmp_path / "run.parquet"
    assert wmrid("simulate", "--duration", "1", "-o", str(parquet)).returncode == 0
    cases = {
        "run.parquet.gz": (gzip.compress(parquet.read_bytes()), "a gzip-compressed Parquet file", "gunzip -k"),
        "log.gz": (gzip.compress(parquet.read_bytes()), "a gzip-compressed Parquet file", "gunzip -k"),
        "rec.mcap.zst": (COMPRESS["zstd"][1](b"\x89MCAP0\r\n" + bytes(64)), "zstd-compressed MCAP", "zstd -d"),
        "run.bag.bz2": (bz2.compress(b"#ROSBAG V2.0\n" + bytes(64)), "bzip2-compressed file holding a ROS 1 bag", ""),
    }
    for name, (data, needle, command) in cases.items():
        (tmp_path / name).write_bytes(data)
        out = wmrid("identify", str(tmp_path / name))
        assert out.returncode == 2, name
        err = out.stderr.decode()
        assert needle in err, err
        assert command in err, err


def test_a_compression_bomb_of_binary_is_refused_from_its_first_bytes(tmp_path):
    """200 MB of NUL bytes in a 200 kB gzip: refused from the first 64 kB decompressed, not decompressed whole."""
    path = tmp_path / "bomb.csv.gz"
    path.write_bytes(gzip.compress(bytes(200 << 20), compresslevel=9))
    assert path.stat().st_size < 1 << 20
    out = wmrid("identify", str(path))
    assert out.returncode == 2
    assert "NUL byte" in out.stderr.decode()


def test_inspect_shows_a_compressed_csv(tmp_path, plain):
    path = tmp_path / "run.csv.bz2"
    path.write_bytes(bz2.compress(plain.read_bytes()))
    out = wmrid("inspect", str(path), "--format", "json")
    assert out.returncode == 0, out.stderr.decode()
    info = json.loads(out.stdout)
    assert {"t", "eta_r", "eta_l", "tau_r", "tau_l"} <= {c["name"] for c in info["columns"]}
    assert any("bzip2-compressed" in n for n in info["notes"]), info["notes"]


@pytest.mark.parametrize("kind", sorted(COMPRESS))
def test_concatenated_streams_are_read_whole(tmp_path, plain, kind):
    """``cat a.gz b.gz`` (or zstd frames, bzip2 and xz streams) decompresses to the concatenation: the log is
    split between two streams mid-row, and still reads as the plain file."""
    suffix, compress = COMPRESS[kind]
    data = plain.read_bytes()
    cut = len(data) // 2 + 7  # inside a row
    path = tmp_path / f"two.csv{suffix}"
    path.write_bytes(compress(data[:cut]) + compress(data[cut:]))
    whole = read_log(str(plain))
    log = read_log(str(path))
    assert np.array_equal(log.t, whole.t)
    assert np.array_equal(log.eta, whole.eta)
    assert np.array_equal(log.tau, whole.tau)


def test_a_zstd_stream_is_read_in_bounded_steps_and_a_skippable_frame_first_is_recognised(tmp_path, plain):
    """A 1 KiB step of compressed input at a time (a bomb cannot make one read huge), and a stream that starts with
    a skippable frame (as pzstd writes) is zstd all the same."""
    import io
    import struct

    from wmrid.io.sources import _ZstdReader

    bomb = zstandard.ZstdCompressor().compress(bytes(64 << 20))
    reader = _ZstdReader(io.BytesIO(bomb))
    assert len(reader.read(10)) == 10
    assert len(reader._buf) < 48 << 20  # one step's output, not the 64 MiB
    skippable = struct.pack("<II", 0x184D2A50, 4) + b"skip"
    path = tmp_path / "skip.csv.zst"
    path.write_bytes(skippable + COMPRESS["zstd"][1](plain.read_bytes()))
    assert np.array_equal(read_log(str(path)).eta, read_log(str(plain)).eta)
