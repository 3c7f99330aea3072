"""The Python package against the command line and against finite differences.

Run from the workspace root after `pip install ./python` (scripts/test.sh
does both); KINEGEN_BIN names the command line to compare with (default:
target/debug/kinegen).
"""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import kinegen

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "spec" / "diff_drive.toml"
LOG = ROOT / "data" / "mystery_robot.csv"
BIN = os.environ.get("KINEGEN_BIN", str(ROOT / os.environ.get("CARGO_TARGET_DIR", "target") / "debug" / "kinegen"))


def cli_json(*args):
    out = subprocess.run([BIN, *args, "--json", "-"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.fixture(scope="module")
def model():
    return kinegen.Model.from_file(str(SPEC))


@pytest.fixture(scope="module")
def log(model):
    return kinegen.read_log(str(LOG), model)


def test_a_model_lists_what_its_spec_declares(model):
    assert model.states == ["x", "y", "theta"]
    assert [i.column for i in model.inputs] == ["enc_r", "enc_l"]
    assert [p.name for p in model.parameters] == ["r_r", "r_l", "b", "counts_per_rev", "gear_ratio"]
    b = model.parameters[2]
    assert (b.nominal, b.unit, b.min, b.free) == (0.2, "m", 0.0, True)
    assert model.nominal_parameters().tolist() == [p.nominal for p in model.parameters]


def test_a_straight_step_moves_the_robot_by_the_wheels_distance(model):
    # 1000 counts/s on both wheels for 0.1 s: r * 2 pi gear/counts * 1000 * 0.1 forward
    p = model.nominal_parameters()
    x = model.step(np.zeros((4, 3)), np.full((4, 2), 1000.0), 0.1)
    k = 2 * np.pi * p[4] / p[3]
    assert x.shape == (4, 3)
    np.testing.assert_allclose(x[:, 0], 0.042 * k * 1000 * 0.1, rtol=1e-12)
    np.testing.assert_allclose(x[:, 1:], 0.0, atol=1e-15)


def finite_difference(f, z, h=1e-6):
    cols = []
    for j in range(z.shape[-1]):
        e = np.zeros_like(z)
        e[..., j] = h
        cols.append((f(z + e) - f(z - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_step_jacobians_agree_with_finite_differences(model):
    rng = np.random.default_rng(1)
    n = 50
    x = rng.normal(size=(n, 3))
    u = rng.normal(scale=3000.0, size=(n, 2))
    dt = rng.uniform(0.01, 0.2, size=n)
    p = model.nominal_parameters()
    for exact in (True, False):
        jx = model.step_jac_x(x, u, dt, exact=exact)
        fd = finite_difference(lambda z: model.step(z, u, dt, exact=exact), x)
        np.testing.assert_allclose(jx, fd, atol=1e-7)
        jp = model.step_jac_p(x, u, dt, exact=exact)
        pp = np.tile(p, (n, 1))
        fdp = finite_difference(lambda q: model.step(x, u, dt, q, exact=exact), pp, h=1e-8)
        np.testing.assert_allclose(jp, fdp, rtol=1e-5, atol=1e-6)


def test_observations_and_their_jacobians(model):
    rng = np.random.default_rng(2)
    x = rng.normal(size=(20, 3))
    lm = rng.normal(size=(20, 2)) + 3.0
    z = model.observe("landmark", x, landmark=lm)
    d = lm - x[:, :2]
    np.testing.assert_allclose(z[:, 0], np.hypot(d[:, 0], d[:, 1]), rtol=1e-12)
    j = model.observe("landmark", x, landmark=lm, jac_x=True)
    fd = finite_difference(lambda s: model.observe("landmark", s, landmark=lm), x)
    np.testing.assert_allclose(j, fd, atol=1e-6)
    with pytest.raises(kinegen.UsageError, match="no observation `camera`"):
        model.observe("camera", x)


def test_compare_gives_the_command_lines_document(model, log):
    r = model.compare(log)
    cli = cli_json("compare", "--spec", str(SPEC), "--data", str(LOG))
    assert json.loads(r.to_json()) == cli
    assert r.position_rmse == cli["errors"]["rmse"]
    assert r.track.shape == (len(log), 3)


def test_fit_gives_the_command_lines_estimates(model, log):
    f = model.fit([log])
    cli = cli_json("fit", "--spec", str(SPEC), "--data", str(LOG))
    assert f.after.position_rmse == pytest.approx(cli["after"]["rmse"], rel=1e-12)
    for name, e in cli["parameters"].items():
        assert f.parameters[name].estimate == pytest.approx(e["estimate"], rel=1e-12)
        assert f.parameters[name].std == pytest.approx(e["std"], rel=1e-9)
    assert json.loads(f.to_json()) == cli
    c = f.covariance
    assert c.shape == (len(f.free), len(f.free))
    np.testing.assert_allclose(np.sqrt(np.diag(c)), [f.parameters[n].std for n in f.free], rtol=1e-12)


def test_diagnose_names_what_the_command_line_names(model, log):
    d = model.diagnose([log])
    cli = cli_json("diagnose", "--spec", str(SPEC), "--data", str(LOG))
    assert d.verdict.effect == cli["verdict"]["effect"] == "lateral_slip"
    assert [e["effect"] for e in d.verdict.effects] == [e["effect"] for e in cli["verdict"]["effects"]]
    assert d.verdict.proposed == cli["verdict"]["proposed"]
    assert [c["effect"] for c in d.candidates] == [c["effect"] for c in cli["candidates"]]
    assert d.verdict.apply == cli["verdict"]["apply"]
    assert without_timing(json.loads(d.to_json())) == without_timing(cli)


def without_timing(doc):
    """A diagnosis's document less its timing, which no two runs share."""
    return {k: v for k, v in doc.items() if k != "timing"}


REAL = Path(os.environ.get("KINEGEN_REAL_DATA", ROOT.parent / "shared" / "real"))

# A user's own spec for the OptiOdom differential drive (not bundled): motor
# encoders in ticks, its own parameter names.
WHEELIE = """
name = "wheelie"
state = ["x", "y", "theta"]
[[input]]
name = "right_ticks"
column = "enc_r"
kind = "cumulative"
unit = "tick"
[[input]]
name = "left_ticks"
column = "enc_l"
kind = "cumulative"
unit = "tick"
[[parameter]]
name = "radius_right"
nominal = 0.042
unit = "m"
min = 0.02
max = 0.08
[[parameter]]
name = "radius_left"
nominal = 0.042
unit = "m"
min = 0.02
max = 0.08
[[parameter]]
name = "track"
nominal = 0.205
unit = "m"
min = 0.1
max = 0.4
[[parameter]]
name = "ticks_per_wheel_rev"
nominal = 2796.8
const = true
[[define]]
name = "wr"
expr = "2*pi*right_ticks/ticks_per_wheel_rev"
[[define]]
name = "wl"
expr = "2*pi*left_ticks/ticks_per_wheel_rev"
[motion]
vx = "(radius_right*wr + radius_left*wl)/2"
vy = "0"
omega = "(radius_right*wr - radius_left*wl)/track"
"""


def real_logs(folder, *names):
    """Logs of ../shared/real (or $KINEGEN_REAL_DATA); skipped where absent,
    failed where CI requires them."""
    paths = [REAL / folder / n for n in names]
    if not all(p.is_file() for p in paths):
        if os.environ.get("KINEGEN_REQUIRE_REAL_DATA") == "1":
            pytest.fail(f"the real logs are required and absent: {REAL / folder}")
        pytest.skip(f"SKIPPED: no real logs at {REAL / folder}")
    return paths


def test_real_logs_give_the_command_lines_documents(tmp_path):
    train, held = real_logs("optiodom-diff-square", "run-01.csv", "run-02.csv"), \
        real_logs("optiodom-diff-square", "run-03.csv")
    spec = tmp_path / "wheelie.toml"
    spec.write_text(WHEELIE)
    m = kinegen.Model.from_file(str(spec))
    logs = [kinegen.read_log(str(p), m) for p in train]
    data = [a for p in train for a in ("--data", str(p))]
    assert json.loads(m.compare(logs).to_json()) == cli_json("compare", "--spec", str(spec), *data)
    fit = m.fit(logs, holdout=[kinegen.read_log(str(held[0]), m)])
    assert json.loads(fit.to_json()) == cli_json("fit", "--spec", str(spec), *data, "--holdout", str(held[0]))
    assert fit.after.position_rmse < fit.before.position_rmse
    d = m.diagnose(logs)
    assert without_timing(json.loads(d.to_json())) == without_timing(cli_json("diagnose", "--spec", str(spec), *data))


def test_the_extension_holds_no_symbolica():
    # the full command line's binary names symbolica's functions thousands of
    # times (its panics, its symbols); the extension the package installs
    # differentiates by itself and must not contain it
    from kinegen import _kinegen
    assert b"symbolica" not in Path(_kinegen.__file__).read_bytes()


def test_with_effect_adds_a_catalogue_effect(model):
    slip = model.with_effect("lateral_slip", k_slip=0.1)
    assert [p.name for p in slip.parameters][-1] == "k_slip"
    assert slip.nominal_parameters()[-1] == 0.1
    with pytest.raises(kinegen.UsageError):
        model.with_effect("no_such_effect")
    # checked as `kinegen add-effect` checks it: in its bounds, and once
    with pytest.raises(kinegen.UsageError, match="outside the bounds"):
        model.with_effect("lateral_slip", k_slip=3.0)
    with pytest.raises(kinegen.UsageError, match="already has"):
        slip.with_effect("lateral_slip")


def test_a_bad_spec_is_a_spec_error_with_its_place():
    with pytest.raises(kinegen.SpecError) as e:
        kinegen.Model.from_str('name = "r"\nstate = ["x", "y", "theta"]\n[motion]\nvx = "v +"\nvy = "0"\nomega = "0"\n', name="mine.toml")
    assert isinstance(e.value, kinegen.Error)
    assert (e.value.file, e.value.line) == ("mine.toml", 4)
    assert e.value.column is not None


def test_a_bad_log_is_a_log_error_with_its_row_and_column(model, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,enc_r,enc_l\n0,0,0\n0.1,oops,3\n0.2,5,6\n")
    with pytest.raises(kinegen.LogError) as e:
        kinegen.read_log(str(bad), model)
    assert e.value.file.endswith("bad.csv")
    assert e.value.line == 3
    assert e.value.column == "enc_r"


def test_bad_arrays_are_usage_errors(model):
    with pytest.raises(kinegen.UsageError, match="x: expected shape"):
        model.step(np.zeros((3, 4)), np.zeros((3, 2)), 0.1)
    with pytest.raises(kinegen.UsageError, match="rows"):
        model.step(np.zeros((3, 3)), np.zeros((2, 2)), 0.1)


def test_localize_gives_the_command_lines_document(tmp_path):
    spec = ROOT / "spec" / "unicycle_ekf.toml"
    sim, obs = tmp_path / "sim.csv", tmp_path / "obs.csv"
    beacons = ROOT / "data" / "beacons.csv"
    made = subprocess.run([BIN, "simulate", "--spec", str(spec), "--trajectory", "random", "--seed", "7",
                           "--landmarks", str(beacons), "--observations", str(obs), "--out", str(sim)],
                          capture_output=True, text=True)
    assert made.returncode == 0, made.stderr
    m = kinegen.Model.from_file(str(spec))
    log = kinegen.read_log(str(sim), m, observations=str(obs), landmarks=str(beacons))
    loc = m.localize(log)
    cli = cli_json("localize", "--spec", str(spec), "--data", str(sim), "--observations", str(obs),
                   "--landmarks", str(beacons))
    mine = json.loads(loc.to_json())
    assert mine == cli
    run = loc.runs[0]
    assert run.track.shape == (len(log), 3)
    assert run.covariance.shape == (len(log), 3, 3)
    np.testing.assert_allclose(run.covariance, np.transpose(run.covariance, (0, 2, 1)))
    assert run.innovations.shape == (cli["runs"][0]["observations_used"], 2)
    assert loc.position_rmse == cli["runs"][0]["position_rmse_m"]
    # the filter beats dead reckoning, and its estimate ends where the document says
    assert run.position_rmse < run.dead_reckoning_rmse
    np.testing.assert_array_equal(run.track[-1], cli["runs"][0]["final_pose"])
    with pytest.raises(kinegen.UsageError, match="bogus="):
        m.localize(log, bogus=0.1)


def test_localize_refuses_a_log_without_sightings(model, log):
    with pytest.raises(kinegen.Error):
        model.localize(log)


def test_simulate_writes_what_the_command_line_writes(model, tmp_path):
    sim = model.simulate(trajectory="random", seed=2026, effects={"lateral_slip": 0.2}, b=0.205, r_l=0.0418)
    mine, cli = tmp_path / "mine.csv", tmp_path / "cli.csv"
    sim.write(str(mine))
    made = subprocess.run([BIN, "simulate", "--spec", str(SPEC), "--effect", "lateral_slip=0.2", "--set", "b=0.205",
                           "--set", "r_l=0.0418", "--trajectory", "random", "--seed", "2026", "--out", str(cli)],
                          capture_output=True, text=True)
    assert made.returncode == 0, made.stderr
    assert mine.read_bytes() == cli.read_bytes()
    assert sim.columns[0] == "t" and sim.data.shape == (len(sim), len(sim.columns))
    # read back, the simulated robot's log runs through the analysis
    log = kinegen.read_log(str(mine), model)
    np.testing.assert_allclose(log.t, sim.data[:, 0] - sim.data[0, 0], atol=1e-8)  # 9 decimals in the file


def test_simulate_refuses_an_unknown_effect_and_trajectory(model):
    with pytest.raises(kinegen.UsageError):
        model.simulate(effects={"no_such_effect": 0.1})
    with pytest.raises(kinegen.UsageError):
        model.simulate(trajectory="zigzag")
    with pytest.raises(kinegen.UsageError, match="laps=0"):
        model.simulate(laps=0)
