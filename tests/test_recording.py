"""Recordings (``idm-recording/1``): the reader, the synthetic-case writer, and every refusal.

The dev cases are read from ``../shared/recordings/dev`` (skipped when that folder is absent, as
in a user's clone); everything else runs on small cases written by ``idm_rs.io.synthetic``.
"""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

import idm_rs
from idm_rs.core.waveforms import voltage_at
from idm_rs.io.recording import Experiment, Recording, RecordingError, load_case
from idm_rs.io.synthetic import make_case

DEV = Path(__file__).resolve().parents[2] / "shared" / "recordings" / "dev"
DEV_CASES = sorted(p.name for p in DEV.glob("dev*") if (p / "meta.json").is_file()) if DEV.is_dir() else []

#: the offsets of the shared synthetic case [m] (given, so x in µm is flagged on line 2)
OFFSETS = (5e-7, -1.2e-6)
F1 = "exp1_forward_80V_200Hz.csv"
F2 = "exp2_backward_60V_200Hz.csv"


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def base_case(tmp_path_factory) -> Path:
    """The default synthetic case (2 files, 2 cycles at 200 Hz, lps), written once."""
    return make_case(tmp_path_factory.mktemp("base") / "case", nominal_params=idm_rs.Params(), offsets=OFFSETS)


@pytest.fixture
def case(base_case, tmp_path) -> Path:
    """A fresh copy of the base case, to corrupt."""
    return Path(shutil.copytree(base_case, tmp_path / "case"))


def read_meta(case: Path) -> dict:
    return json.loads((case / "meta.json").read_text())


def write_meta(case: Path, meta: dict) -> None:
    (case / "meta.json").write_text(json.dumps(meta, indent=2))


def read_lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def write_lines(path: Path, lines: list[str]) -> None:
    path.write_text("\n".join(lines) + "\n")


def set_cell(path: Path, line: int, column: int, value: str) -> None:
    """Replace the value in ``line`` (1-based, header = 1) and ``column`` (0-based)."""
    lines = read_lines(path)
    cells = lines[line - 1].split(",")
    cells[column] = value
    lines[line - 1] = ",".join(cells)
    write_lines(path, lines)


def map_column(path: Path, column: int, f) -> None:
    lines = read_lines(path)
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[column] = f"{f(float(cells[column])):.10g}"
        out.append(",".join(cells))
    write_lines(path, out)


def refused(case: Path, *fragments: str, line=None, column=None) -> RecordingError:
    """load_case(case) must raise a RecordingError whose message holds every fragment."""
    with pytest.raises(RecordingError) as info:
        load_case(case)
    err = info.value
    msg = str(err)
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"
    if line is not None:
        assert err.line == line, msg
        assert f"line {line}" in msg
    if column is not None:
        assert err.column == column, msg
    return err


# --------------------------------------------------------------------------------------------
# dev cases
# --------------------------------------------------------------------------------------------
@pytest.mark.skipif(not DEV_CASES, reason=f"no dev recordings at {DEV}")
@pytest.mark.parametrize("name", DEV_CASES or ["-"])
def test_dev_case_loads_consistently(name):
    path = DEV / name
    meta = json.loads((path / "meta.json").read_text())
    t0 = time.perf_counter()
    rec = load_case(path)
    elapsed = time.perf_counter() - t0
    assert elapsed < 1.0, f"loading {name} took {elapsed:.2f} s"  # ~0.02-0.08 s here; target 0.3 s

    assert isinstance(rec, Recording) and rec.name == name
    assert rec.sample_rate_Hz == meta["sensor"]["sample_rate_Hz"]
    assert rec.resolution_m == meta["sensor"]["resolution_m"]
    nom = meta["nominal"]
    assert rec.nominal.model == nom["model"]
    assert rec.nominal.piezo_hysteresis == nom["piezo_hysteresis"]
    assert rec.nominal.n_elements == (nom["n_elements"] if nom["model"] == "dps" else 1)
    # every parameter the case gives, as given; the operating load (not in the format) is none
    assert rec.nominal.params.to_dict(resolved=False) == pytest.approx({"load_force": 0.0, **nom["params"]}, rel=0)
    assert rec.nominal.params.normal_force == nom["params"]["normal_force"]  # explicit, not derived

    assert [e.file for e in rec] == [e["file"] for e in meta["experiments"]]
    step = 1.0 / rec.sample_rate_Hz
    for e, m in zip(rec, meta["experiments"]):
        assert isinstance(e, Experiment)
        n = int(round(e.duration / step)) + 1
        assert e.t.shape == e.voltage.shape == e.x.shape == (n,)
        assert e.t[0] == 0.0 and e.t[-1] == pytest.approx(m["rest_s"] + m["cycles"] / m["frequency_Hz"])
        np.testing.assert_allclose(np.diff(e.t), step, rtol=1e-6)
        w = e.waveform
        assert (w.amplitude, w.frequency, w.cycles, w.direction, w.rise, w.delay) == (
            m["amplitude_V"], m["frequency_Hz"], m["cycles"], m["direction"], m["edge_s"], m["rest_s"])
        assert w.duration == pytest.approx(e.duration)
        np.testing.assert_allclose(e.voltage, voltage_at(w, e.t), atol=1e-6 * abs(w.amplitude))
        q = e.x / rec.resolution_m
        np.testing.assert_allclose(q, np.round(q), atol=1e-3)
        assert np.max(np.abs(e.x)) < 1e-4  # µm scale, in metres
        assert e.rest_mask.sum() == int(round(e.rest_s / step))


@pytest.mark.skipif(not (DEV / "KEY.json").is_file(), reason=f"no dev key at {DEV}")
@pytest.mark.parametrize("name", DEV_CASES or ["-"])
def test_dev_rest_segment_noise_matches_key(name):
    """Before the first cycle the device rests: x there is offset + noise (in metres)."""
    key = json.loads((DEV / "KEY.json").read_text())[name]
    rec = load_case(DEV / name)
    resid = []
    for e, offset in zip(rec, key["offsets_m"]):
        r = e.rest_mask
        xr = e.x[r]
        assert abs(xr.mean() - offset) < 5 * key["noise_rms_m"] / np.sqrt(r.sum()) + rec.resolution_m
        resid.append(xr - xr.mean())
    pooled = np.sqrt(np.sum(np.concatenate(resid) ** 2) / (sum(map(len, resid)) - len(resid)))
    assert pooled == pytest.approx(key["noise_rms_m"], rel=0.15)


# --------------------------------------------------------------------------------------------
# synthetic cases: round trip
# --------------------------------------------------------------------------------------------
def test_base_case_round_trip(base_case):
    rec = Recording.load(base_case)
    assert rec.name == "case" and len(rec) == 2 and [e.file for e in rec] == [F1, F2]
    assert rec.nominal == load_case(base_case).nominal
    assert rec.nominal.model == "lps" and rec.nominal.n_elements == 1 and not rec.nominal.piezo_hysteresis
    assert rec.nominal.params == idm_rs.Params(normal_force=idm_rs.Params().effective_normal_force)
    meta = read_meta(base_case)
    assert "n_elements" not in meta["nominal"]
    assert list(meta["nominal"]["params"]) == [f for f in idm_rs.Params.__dataclass_fields__]
    assert meta["experiments"][0]["amplitude_V"] == 80 and isinstance(meta["experiments"][0]["amplitude_V"], int)
    assert (base_case / F1).read_text().startswith("t,voltage,x\n0,0,")
    for e in rec:
        assert e.t.size == 1201 and e.duration == pytest.approx(0.012)
        np.testing.assert_allclose(e.voltage, voltage_at(e.waveform, e.t), rtol=1e-9, atol=1e-12)
        assert rec[e.name] is e and rec[e.file] is e
    # offsets land where asked: the rest segment is at the offset, up to noise
    for e, off in zip(rec, OFFSETS):
        assert abs(e.x[e.rest_mask].mean() - off) < 1e-9


def test_noise_free_reading_matches_simulate(tmp_path):
    """Nominal in meta, truth in the data: x − offset is the true device's reading."""
    nominal = idm_rs.Params(mu_k=0.5, mu_s=0.5)
    true = nominal.replace(d33=1.3e-7, m2=0.32)
    effects = idm_rs.Effects(drift_rate=2e-6)
    exps = [dict(amplitude_V=70, frequency_Hz=250, direction="backward", cycles=2, rest_s=0.001)]
    path = make_case(
        tmp_path / "c", nominal_params=nominal, true_params=true, model="lps", true_model="dps",
        true_n_elements=3, true_piezo_hysteresis=True, effects=effects, experiments=exps,
        noise_rms=0.0, resolution=None, offsets=[1.5e-6], sample_rate_Hz=2e5,
    )
    rec = load_case(path)
    assert rec.sample_rate_Hz == 2e5 and rec.resolution_m == 0.0
    assert rec.nominal.params == nominal.replace(normal_force=nominal.effective_normal_force)
    assert rec.nominal.model == "lps"
    (e,) = rec.experiments
    assert e.file == "exp1_backward_70V_250Hz.csv" and e.rest_s == 0.001
    sim = idm_rs.simulate(true, e.waveform, e.duration, 1e-8, "dps", 3, save_every=500,
                          piezo_hysteresis=True, effects=effects)
    np.testing.assert_allclose(e.t, sim.t, atol=1e-12)
    np.testing.assert_allclose(e.x - 1.5e-6, sim.reading, rtol=0, atol=1e-15)
    np.testing.assert_allclose(e.voltage, sim.voltage, atol=1e-8)


def test_noise_quantisation_and_seed(tmp_path):
    exps = [dict(amplitude_V=50, frequency_Hz=200, direction="forward", cycles=2)]
    kw = dict(nominal_params=idm_rs.Params(), experiments=exps, noise_rms=2e-9, resolution=5e-10)
    a = load_case(make_case(tmp_path / "a", seed=1, **kw))
    b = load_case(make_case(tmp_path / "b", seed=1, **kw))
    c = load_case(make_case(tmp_path / "c", seed=2, **kw))
    np.testing.assert_array_equal(a[0].x, b[0].x)
    assert not np.array_equal(a[0].x, c[0].x)
    sim = idm_rs.simulate(idm_rs.Params(), a[0].waveform, a[0].duration, 1e-8, "lps", save_every=1000,
                          piezo_hysteresis=False)
    for rec in (a, c):
        e = rec[0]
        q = e.x / 5e-10
        np.testing.assert_allclose(q, np.round(q), atol=1e-6)
        resid = e.x - sim.reading
        offset = resid.mean()
        assert abs(offset) <= 2e-6
        # white noise of 2 nm plus quantisation (0.14 nm): 1201 samples, ±10 %
        assert np.std(resid) == pytest.approx(np.hypot(2e-9, 5e-10 / np.sqrt(12)), rel=0.1)
        assert abs(np.corrcoef(resid[:-1], resid[1:])[0, 1]) < 0.15


def test_make_case_refuses_bad_settings(tmp_path):
    p = idm_rs.Params()
    with pytest.raises(ValueError, match="divide"):
        make_case(tmp_path / "a", nominal_params=p, dt=3e-8)
    with pytest.raises(ValueError, match="offsets"):
        make_case(tmp_path / "b", nominal_params=p, offsets=[0.0])
    with pytest.raises(ValueError, match="unknown key"):
        make_case(tmp_path / "c", nominal_params=p, experiments=[dict(amplitude_V=1, frequency_Hz=200,
                                                                       direction="forward", cycles=1, foo=1)])


def test_crlf_and_trailing_blank_lines_are_accepted(case):
    before = load_case(case).experiments
    text = (case / F1).read_text()
    (case / F1).write_text(text.replace("\n", "\r\n") + "\r\n")
    after = load_case(case).experiments
    # the same samples, none lost or added by the line endings or the blank line
    assert len(after) == len(before)
    for a, b in zip(after, before):
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.voltage, b.voltage)


# --------------------------------------------------------------------------------------------
# refusals: meta.json
# --------------------------------------------------------------------------------------------
def test_recording_error_is_a_value_error(case):
    (case / "meta.json").unlink()
    err = refused(case, "meta.json", "missing")
    assert isinstance(err, ValueError) and err.file == case / "meta.json"


def test_not_a_directory(tmp_path):
    refused(tmp_path / "nowhere", "nowhere", "not a directory")


def test_bad_json_names_line_and_column(case):
    lines = read_lines(case / "meta.json")
    k = next(i for i, s in enumerate(lines) if '"model": "lps",' in s)
    lines[k] = lines[k].rstrip(",")  # a missing comma: the parser stops on the next line
    write_lines(case / "meta.json", lines)
    err = refused(case, "meta.json", "invalid JSON", "column", line=k + 2)
    assert re.search(r"column \d+", str(err))


def test_wrong_format_id(case):
    meta = read_meta(case)
    meta["format"] = "idm-recording/2"
    write_meta(case, meta)
    refused(case, "meta.json", "'idm-recording/2'", "idm-recording/1", column="format")


@pytest.mark.parametrize(
    "where,key,expect",
    [
        ((), "sensor", "'sensor'"),
        ((), "format", "'format'"),
        (("sensor",), "resolution_m", "'sensor.resolution_m'"),
        (("nominal",), "params", "'nominal.params'"),
        (("experiments", 1), "frequency_Hz", "'experiments[1].frequency_Hz'"),
        (("experiments", 0), "edge_s", "'experiments[0].edge_s'"),
    ],
)
def test_missing_key(case, where, key, expect):
    meta = read_meta(case)
    obj = meta
    for w in where:
        obj = obj[w]
    del obj[key]
    write_meta(case, meta)
    refused(case, "meta.json", "missing key", expect)


def test_unknown_parameter_name(case):
    meta = read_meta(case)
    meta["nominal"]["params"]["mu_kk"] = 0.5
    write_meta(case, meta)
    refused(case, "meta.json", "unknown parameter", "'mu_kk'", column="nominal.params")


def test_missing_parameter(case):
    meta = read_meta(case)
    del meta["nominal"]["params"]["normal_force"]
    write_meta(case, meta)
    refused(case, "meta.json", "missing parameter", "'normal_force'")


def test_invalid_parameter_value(case):
    meta = read_meta(case)
    meta["nominal"]["params"]["m1"] = -0.4
    write_meta(case, meta)
    refused(case, "meta.json", "m1", column="nominal.params")
    meta["nominal"]["params"]["m1"] = "0.4"
    write_meta(case, meta)
    refused(case, "meta.json", "must be a number", column="nominal.params.m1")


def test_dps_needs_n_elements(case):
    meta = read_meta(case)
    meta["nominal"]["model"] = "dps"
    write_meta(case, meta)
    refused(case, "meta.json", "nominal.n_elements")
    meta["nominal"]["n_elements"] = 3
    write_meta(case, meta)
    assert load_case(case).nominal.n_elements == 3
    meta["nominal"]["model"] = "fem"
    write_meta(case, meta)
    refused(case, "meta.json", "'fem'", column="nominal.model")


def test_bad_experiment_entries(case):
    meta = read_meta(case)
    meta["experiments"][0]["direction"] = "sideways"
    write_meta(case, meta)
    refused(case, "meta.json", "'sideways'", column="experiments[0].direction")
    meta["experiments"][0]["direction"] = "forward"
    meta["experiments"][1] = dict(meta["experiments"][0])
    write_meta(case, meta)
    refused(case, "meta.json", "listed twice", column="experiments[1].file")
    meta["experiments"][1]["file"] = "../elsewhere.csv"
    write_meta(case, meta)
    refused(case, "meta.json", "plain file name", column="experiments[1].file")


def test_an_experiment_may_be_recorded_with_the_rig_turned_end_for_end(case):
    """``orientation`` is optional ("normal"), "reversed" is read, anything else is refused
    by name with the two accepted values."""
    assert [e.orientation for e in load_case(case).experiments] == ["normal"] * len(read_meta(case)["experiments"])
    meta = read_meta(case)
    meta["experiments"][1]["orientation"] = "reversed"
    write_meta(case, meta)
    rec = load_case(case)
    assert rec.experiments[1].is_reversed and not rec.experiments[0].is_reversed
    meta["experiments"][1]["orientation"] = "upside down"
    write_meta(case, meta)
    refused(case, "meta.json", "'upside down'", "\"reversed\"", column="experiments[1].orientation")


def test_meta_disagrees_with_file_name(case):
    meta = read_meta(case)
    meta["experiments"][0]["direction"] = "backward"
    write_meta(case, meta)
    refused(case, "meta.json", F1, "direction", column="experiments[0].direction")


# --------------------------------------------------------------------------------------------
# refusals: CSV files
# --------------------------------------------------------------------------------------------
def test_listed_csv_is_absent(case):
    (case / F2).unlink()
    refused(case, F2, "missing", "experiments[1].file")


@pytest.mark.parametrize(
    "header,expect",
    [
        ("t,voltage", "missing column 'x'"),
        ("time,voltage,x", "missing column 't'; extra column 'time' (column 1)"),
        ("index,t,voltage,x", "extra column 'index' (column 1)"),
        ("t,x,voltage", "wrong order"),
        ("t, voltage, x", "no spaces"),
    ],
)
def test_header_must_be_exact(case, header, expect):
    lines = read_lines(case / F1)
    lines[0] = header
    write_lines(case / F1, lines)
    refused(case, F1, expect, line=1)


def test_missing_header(case):
    lines = read_lines(case / F1)
    write_lines(case / F1, lines[1:])
    refused(case, F1, "no header", line=1)


def test_non_numeric_value(case):
    set_cell(case / F1, 57, 2, "abc")
    err = refused(case, F1, "not a number", "'abc'", "column 3 ('x')", line=57, column="x")
    assert str(err).startswith(str(case / F1) + ", line 57, column 3 ('x')")


@pytest.mark.parametrize("value,column,name", [("nan", 1, "voltage"), ("inf", 2, "x"), ("-inf", 0, "t")])
def test_non_finite_value(case, value, column, name):
    set_cell(case / F2, 100, column, value)
    refused(case, F2, "not finite", f"'{value}'", f"column {column + 1} ('{name}')", line=100, column=name)


def test_wrong_number_of_values(case):
    lines = read_lines(case / F1)
    lines[199] = lines[199].rsplit(",", 1)[0]  # line 200 loses its x
    write_lines(case / F1, lines)
    refused(case, F1, "2 values, expected 3", line=200)


def test_empty_line_inside(case):
    lines = read_lines(case / F1)
    lines.insert(300, "")  # becomes line 301
    write_lines(case / F1, lines)
    refused(case, F1, "empty line", line=301)


def test_non_uniform_time_step(case):
    lines = read_lines(case / F1)
    del lines[299]  # sample 298 (line 300) dropped: line 300 now jumps two steps
    write_lines(case / F1, lines)
    refused(case, F1, "non-uniform time step", "expected 1e-05 s", line=300, column="t")


def test_slightly_wrong_time(case):
    set_cell(case / F1, 500, 0, "0.00498")  # sample 498 at 4.98 ms is written as 4.98 ms (ok) ...
    load_case(case)
    set_cell(case / F1, 500, 0, "0.004983")  # ... but not 30 % of a step off
    refused(case, F1, "non-uniform", line=500, column="t")


def test_time_going_backwards(case):
    set_cell(case / F1, 40, 0, "0.0003")
    refused(case, F1, "does not increase", line=40, column="t")


def test_time_must_start_at_zero(case):
    map_column(case / F1, 0, lambda t: t + 1e-5)
    refused(case, F1, "start at 0", line=2, column="t")


@pytest.mark.parametrize("scale,unit", [(1e6, "µm"), (1e9, "nm")])
def test_x_not_in_metres(case, scale, unit):
    map_column(case / F2, 2, lambda x: x * scale)
    refused(case, F2, "not in metres", unit, line=2, column="x")


def test_voltage_amplitude_disagrees_with_meta(case):
    map_column(case / F1, 1, lambda v: v / 1000)  # written in kV
    refused(case, F1, "amplitude_V = 80", "meta.json disagrees", "experiments[0]", line=252, column="voltage")


def test_sample_rate_disagrees_with_meta(case):
    meta = read_meta(case)
    meta["sensor"]["sample_rate_Hz"] = 2e5
    write_meta(case, meta)
    refused(case, F1, "sample_rate_Hz = 200000", "100000 Hz", "meta.json disagrees")


def test_time_in_milliseconds(case):
    map_column(case / F1, 0, lambda t: t * 1e3)
    refused(case, F1, "t is in ms", "meta.json disagrees", line=3, column="t")


def test_last_sample_disagrees_with_meta(case):
    meta = read_meta(case)
    meta["experiments"][1]["cycles"] = 3
    write_meta(case, meta)
    refused(case, F2, "last sample", "0.017", "meta.json disagrees", line=1202, column="t")


def test_truncated_file(case):
    lines = read_lines(case / F2)
    write_lines(case / F2, lines[:-10])
    refused(case, F2, "last sample at t = 0.0119", "0.012", line=1192)


def test_voltage_off_the_sawtooth(case):
    lines = read_lines(case / F1)
    v = float(lines[399].split(",")[1])
    set_cell(case / F1, 400, 1, f"{v + 2.0:.10g}")  # 2.5 % of 80 V
    refused(case, F1, "differs from the sawtooth", "meta.json disagrees", line=400, column="voltage")
    set_cell(case / F1, 400, 1, f"{v + 0.5:.10g}")  # 0.6 %: within tolerance
    load_case(case)


def test_direction_swapped_in_meta_hints(case):
    # with a file name that does not spell the direction, the voltage check catches it
    (case / F1).rename(case / "first.csv")
    meta = read_meta(case)
    meta["experiments"][0]["file"] = "first.csv"
    meta["experiments"][0]["direction"] = "backward"
    write_meta(case, meta)
    refused(case, "first.csv", "differs from the sawtooth", "holds a forward sawtooth", column="voltage")


def test_resolution_disagrees_with_meta(case):
    meta = read_meta(case)
    meta["sensor"]["resolution_m"] = 1e-9
    write_meta(case, meta)
    err = refused(case, F1, "not a multiple of sensor.resolution_m", "meta.json disagrees", column="x")
    assert err.line is not None and err.line >= 2
