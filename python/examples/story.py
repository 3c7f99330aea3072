"""The kinegen story in Python: compare, diagnose, add the effect, fit, and
plot the error before and after (run by scripts/test.sh; writes story.png).

    python python/examples/story.py [OUT.png]
"""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import kinegen  # noqa: E402

root = Path(__file__).resolve().parents[2]
model = kinegen.Model.from_file(str(root / "spec" / "diff_drive.toml"))
log = kinegen.read_log(str(root / "data" / "mystery_robot.csv"), model)

before = model.compare(log)
print(f"nominal model: position RMSE {before.position_rmse:.3f} m")

d = model.diagnose([log])
print(f"missing effect: {d.verdict.effect}")
step = d.verdict.effects[0]
values = {k: v["estimate"] for k, v in step["parameters"].items()}
with_effect = model.with_effect(d.verdict.effect, **values)

fit = with_effect.fit([log])
print(f"with {d.verdict.effect}, calibrated: {fit.before.position_rmse:.4f} -> {fit.after.position_rmse:.4f} m")
calibrated = {name: e.estimate for name, e in fit.parameters.items()}
after = with_effect.compare(log, **calibrated)

gt = log.ground_truth
t = log.t
err_before = np.hypot(*(before.track[:, :2] - gt[:, :2]).T)
err_after = np.hypot(*(after.track[:, :2] - gt[:, :2]).T)
assert err_after.mean() < 0.2 * err_before.mean(), "the calibrated model with its effect follows the robot"

fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
a.plot(gt[:, 0], gt[:, 1], "k", label="ground truth")
a.plot(before.track[:, 0], before.track[:, 1], label="nominal spec")
a.plot(after.track[:, 0], after.track[:, 1], label=f"with {d.verdict.effect}, calibrated")
a.set_aspect("equal")
a.set_xlabel("x (m)")
a.set_ylabel("y (m)")
a.legend()
b.plot(t, err_before, label="nominal spec")
b.plot(t, err_after, label=f"with {d.verdict.effect}, calibrated")
b.set_xlabel("t (s)")
b.set_ylabel("position error (m)")
b.legend()
out = sys.argv[1] if len(sys.argv) > 1 else "story.png"
fig.tight_layout()
fig.savefig(out, dpi=90)
print(f"wrote {out}")
