"""`python -m scode.batch` on a local Ray: rows for every model, failures included, the
time limit, and a rerun that does no work."""

import shutil

import pytest

pytest.importorskip("ray")
pq = pytest.importorskip("pyarrow.parquet")

import scode  # noqa: E402
from scode import batch  # noqa: E402

from test_scode import corpus_dir  # noqa: E402


def manifest(out):
    return pq.read_table(out / batch.MANIFEST_DIR).to_pylist()


def test_batch_converts_records_failures_and_skips_done(tmp_path, capsys):
    corpus = corpus_dir()
    src = tmp_path / "in"
    (src / "parts").mkdir(parents=True)
    shutil.copy(corpus / "tess" / "screw_coarse.obj", src / "screw_coarse.obj")
    shutil.copy(corpus / "step" / "screw.step", src / "parts" / "screw.step")
    (src / "parts" / "broken.stl").write_bytes(b"solid broken\nfacet normal 0 0\n")
    (src / "readme.txt").write_text("not a model")
    out = tmp_path / "out"

    assert batch.main([str(src), str(out), "--timeout", "300"]) == 0
    rows = {r["source"]: r for r in manifest(out)}
    assert set(rows) == {"screw_coarse.obj", "parts/screw.step", "parts/broken.stl"}
    for name in ["screw_coarse.obj", "parts/screw.step"]:
        r = rows[name]
        assert r["status"] == "ok", r
        data = (out / r["output"]).read_bytes()
        assert r["bytes_out"] == len(data)
        assert r["bytes_in"] == (src / name).stat().st_size
        assert 0 < r["max_error"] < 10 * r["tolerance"]
        assert r["encode_seconds"] > 0
        assert len(set(scode.decode(data).names)) == 10
    broken = rows["parts/broken.stl"]
    assert broken["status"] == "failed" and broken["error"]
    assert broken["bytes_out"] is None
    assert not (out / "parts" / "broken.stl.scode").exists()
    parts = sorted((out / batch.MANIFEST_DIR).glob("*.parquet"))

    capsys.readouterr()
    assert batch.main([str(src), str(out)]) == 0
    assert "converting 0" in capsys.readouterr().out
    assert sorted((out / batch.MANIFEST_DIR).glob("*.parquet")) == parts
    assert len(manifest(out)) == 3

    # A converted model whose .scode went missing is converted again, and so are failures
    # when asked.
    (out / "screw_coarse.obj.scode").unlink()
    assert batch.main([str(src), str(out), "--retry-failed"]) == 0
    again = [r["source"] for r in manifest(out)]
    assert sorted(again) == sorted(list(rows) + ["screw_coarse.obj", "parts/broken.stl"])
    assert (out / "screw_coarse.obj.scode").is_file()


def test_batch_time_limit_is_a_row(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(corpus_dir() / "step" / "screw.step", src / "screw.step")
    out = tmp_path / "out"
    # No child process starts Python and encodes a STEP file in 10 ms.
    assert batch.main([str(src), str(out), "--timeout", "0.01"]) == 0
    (row,) = manifest(out)
    assert row["status"] == "timeout" and "0.01 s" in row["error"]
    assert not (out / "screw.step.scode").exists()
