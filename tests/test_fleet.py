"""Fleets on Dask: a real scheduler and two worker processes on loopback."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason="hystid fleet needs dask.distributed")
pd = pytest.importorskip("pandas", reason="hystid fleet writes its table with pandas")
pytest.importorskip("pyarrow", reason="hystid fleet writes Parquet with pyarrow")

from hystid.baselines import compare  # noqa: E402
from hystid.cli import main  # noqa: E402
from hystid.diagnose import diagnose  # noqa: E402
from hystid.fleet import (  # noqa: E402
    FailedSeed,
    FleetError,
    Job,
    find_jobs,
    map_seeds,
    read_results,
    result_paths,
    run_fleet,
    spawn_seeds,
)
from hystid.identify import identify  # noqa: E402
from hystid.testing import as_measured_suite, stage_b_like  # noqa: E402

CASES = ("offset", "units", "10kHz")


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(host="127.0.0.1", n_workers=2, threads_per_worker=1,
                                  processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as cl:
        yield cl


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory) -> Path:
    """Bouc-Wen stage records as measured (offset, other units, 10 kHz) with held-out
    partners, a stage-B look-alike (200 Hz, large offset) without one, a broken file and a
    table naming a file that does not exist."""
    root = tmp_path_factory.mktemp("fleet")
    recs = {r.name: r for r in as_measured_suite(3, seconds=0.1, hysteresis="bouc_wen")}
    lines = ["name,train,val"]
    (root / "held").mkdir()
    for case in CASES:
        recs[case].save(root / f"{case}.csv")
        recs[f"{case}/heldout"].save(root / "held" / f"{case}.npz")
        lines.append(f"{case},{case}.csv,held/{case}.npz")
    stage_b_like(seconds=3.0, seed=5).save(root / "stage_b.csv")
    lines.append("stage_b,stage_b.csv,")
    (root / "broken.csv").write_text("t,u,y\n0,1,2\n0.001,x,3\n")
    lines.append("broken,broken.csv,")
    lines.append("missing,nowhere.csv,")
    (root / "fleet.csv").write_text("\n".join(lines) + "\n")
    return root


def _table(out: Path) -> pd.DataFrame:
    return read_results(out, "identify").set_index("name")


def test_table_is_the_in_process_comparison_and_a_broken_record_is_isolated(
        client, fleet_dir, tmp_path):
    table = run_fleet(fleet_dir / "fleet.csv", tmp_path, client=client, progress=False)
    assert sorted(table["name"]) == sorted([*CASES, "stage_b", "broken", "missing"])
    t = table.set_index("name")
    # the broken records are failed rows naming the file and what is wrong; the rest go on
    assert t.loc["broken", "status"] == "failed"
    assert "broken.csv, line 3" in t.loc["broken", "error"]
    assert t.loc["missing", "status"] == "failed" and "nowhere.csv" in t.loc["missing", "error"]
    ok = t[t["status"] == "ok"]
    assert sorted(ok.index) == sorted([*CASES, "stage_b"])
    assert ok["worker"].str.startswith("tcp://127.0.0.1:").all()
    # a worker's row is what identify + compare give in this process
    from hystid.records import load_record

    for case in CASES:
        train = load_record(fleet_dir / f"{case}.csv")
        val = load_record(fleet_dir / "held" / f"{case}.npz")
        row = compare(identify(train).model, train, [val]).rows[0]
        for key in ("model", "static_line", "linear"):
            assert ok.loc[case, f"rms_{key}"] == pytest.approx(row[key], rel=1e-6), (case, key)
        assert bool(ok.loc[case, "beats_baselines"]) == row["beats"]
        assert ok.loc[case, "samples"] == train.n and ok.loc[case, "fs"] == train.fs
    # without a held-out record the end of the record is held out
    assert ok.loc["stage_b", "held_out"] == "last 40 % of the excitation"
    assert ok.loc["stage_b", "samples"] == round(0.6 * 600)
    assert np.isfinite(ok[["rms_model", "rms_static_line", "rms_linear"]].to_numpy(float)).all()
    # the default member is identify's (chosen per record): each row has its member's parameters
    first = {"duhem": "param_alpha", "pi-stage": "param_mu0"}
    assert set(ok["model"]) <= set(first)
    for name, model in ok["model"].items():
        assert np.isfinite(float(ok.loc[name, first[model]])), name
    # CSV and Parquet hold the same table; no temporary file is left behind
    csv_path, parquet_path = result_paths(tmp_path, "identify")
    from_csv = pd.read_csv(csv_path, keep_default_na=False, na_values=[""]).set_index("name")
    from_parquet = pd.read_parquet(parquet_path).set_index("name")
    assert np.allclose(from_csv.loc[ok.index, "rms_model"], from_parquet.loc[ok.index,
                                                                             "rms_model"])
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def _same_row(a, b, name) -> bool:
    """The stored row of ``name`` was reused (a rerun writes at least a new timing)."""
    return a.loc[[name]].equals(b.loc[[name]])


def test_resume_skips_done_records_reruns_changed_ones_and_force_reruns_all(
        client, fleet_dir, tmp_path):
    jobs = [j for j in find_jobs(fleet_dir / "fleet.csv") if j.name in ("units", "broken")]
    first = run_fleet(jobs, tmp_path, client=client, progress=False).set_index("name")
    again = run_fleet(jobs, tmp_path, client=client, progress=False).set_index("name")
    # nothing recomputed: every row is the stored one, to the last column
    assert again.equals(first)
    os.utime(fleet_dir / "units.csv")  # the record changed: its row is stale
    third = run_fleet(jobs, tmp_path, client=client, progress=False).set_index("name")
    assert not _same_row(third, first, "units")
    assert _same_row(third, first, "broken")
    retried = run_fleet(jobs, tmp_path, client=client, progress=False,
                        retry_failed=True).set_index("name")
    assert not _same_row(retried, first, "broken")
    assert _same_row(retried, third, "units")
    forced = run_fleet(jobs, tmp_path, client=client, progress=False,
                       force=True).set_index("name")
    assert not any(_same_row(forced, retried, name) for name in forced.index)


def test_diagnose_rows_are_the_diagnosis(client, fleet_dir, tmp_path):
    from hystid.records import load_record

    jobs = [Job("offset", str(fleet_dir / "offset.csv"), (str(fleet_dir / "held/offset.npz"),))]
    settings = {"effects": ["offset", "drift"]}
    row = run_fleet(jobs, tmp_path, "diagnose", settings=settings, client=client,
                    progress=False).iloc[0]
    assert row["status"] == "ok", row["error"]
    res = diagnose(load_record(jobs[0].train), [load_record(jobs[0].val[0])],
                   effects=settings["effects"], progress=False)
    assert row["accepted"] == ";".join(res.accepted)
    assert row["rms_final"] == pytest.approx(res.final["rms_val"], rel=1e-6)
    assert result_paths(tmp_path, "diagnose")[1].exists()


def test_map_seeds_keeps_the_order_and_isolates_a_failing_seed(client):
    seeds = spawn_seeds(11, 6)
    assert len(set(seeds)) == 6
    draw = functools.partial(spawn_seeds, n=3)
    assert map_seeds(draw, seeds, client=client) == [draw(s) for s in seeds]
    kept = map_seeds(draw, [seeds[0], -1, seeds[1]], client=client, errors="keep")
    assert kept[0] == draw(seeds[0]) and kept[2] == draw(seeds[1])
    assert isinstance(kept[1], FailedSeed) and kept[1].seed == -1 and kept[1].error
    with pytest.raises(ValueError):
        map_seeds(draw, [-1], client=client)


def test_command_line_on_an_existing_scheduler(client, fleet_dir, tmp_path, capsys):
    out = tmp_path / "out"
    pattern = str(fleet_dir / "held" / "*.npz")
    status = main(["fleet", "identify", pattern, "--out", str(out), "--scheduler",
                   client.scheduler.address, "--quiet"])
    said = capsys.readouterr().out
    assert status == 0, said
    assert sorted(_table(out).index) == sorted(f"{c}.npz" for c in CASES)
    # one median per output unit (nm and um pooled into one median meant nothing)
    assert _table(out).loc["units.npz", "unit"] == "nm"
    assert "[nm]: median" in said and "[um]: median" in said and "over 2 records" in said
    # bad input: a clear message and exit status 2, nothing written
    assert main(["fleet", "identify", str(fleet_dir / "none*.csv"), "--out",
                 str(tmp_path / "x"), "--scheduler", client.scheduler.address]) == 2
    assert "no record files match" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["fleet", "identify", pattern, "--out", str(out), "--workers", "2",
              "--scheduler", client.scheduler.address])


def test_sources_and_refusals(fleet_dir, tmp_path):
    # a folder: every record file in it (the table too: it is a .csv file like the others)
    assert [j.name for j in find_jobs(fleet_dir)] == sorted(
        [*(f"{c}.csv" for c in CASES), "stage_b.csv", "broken.csv", "fleet.csv"])
    nested = find_jobs(str(fleet_dir / "**" / "*.npz"))
    assert [j.name for j in nested] == sorted(f"{c}.npz" for c in CASES)
    bad = tmp_path / "pairs.csv"
    bad.write_text("train,val\na.csv,b.csv\n,c.csv\n")
    with pytest.raises(FleetError, match="pairs.csv, line 3"):
        find_jobs(bad)
    foreign = tmp_path / "out"
    foreign.mkdir()
    (foreign / "identify.csv").write_text("a,b\n1,2\n")
    with pytest.raises(FleetError, match="not written by hystid fleet"):
        run_fleet([Job("x", "x.csv")], foreign, progress=False)
    assert (foreign / "identify.csv").read_text() == "a,b\n1,2\n"


def test_a_job_takes_any_member_of_the_model_family(fleet_dir):
    """The fleet identifies through the one ``identify(model=..., method=...)``: a PI member's
    row carries its own parameters and names the member; a bad name is a failed row."""
    from hystid.fleet import run_job
    from hystid.records import load_record

    job = Job("offset", str(fleet_dir / "offset.csv"), (str(fleet_dir / "held" / "offset.npz"),))
    row = run_job(job, "identify", {"model": "pi-stage"})
    assert row["status"] == "ok", row["error"]
    assert row["model"] == "pi-stage" and "param_mu0" in row
    record = load_record(job.train)
    direct = identify(record, model="pi-stage")
    assert row["param_mu0"] == pytest.approx(direct.model.params["mu0"], rel=1e-9)
    assert row["samples"] == record.n
    bad = run_job(job, "identify", {"model": "bouc"})
    assert bad["status"] == "failed" and "model: expected 'auto' or one of" in bad["error"]
