"""New physics from outside the package: a plugin distribution with an effect on a new column.

``examples/05_plugin/`` is a user's plugin, a distribution of its own (``aacmm-pin-basetemp``:
``pyproject.toml`` and one module) whose entry point in the group ``aacmm_pin.effects`` adds the
effect ``basetemp``: the A1 encoder reads off in proportion to the temperature of the arm's base,
the campaign column ``temp_base_c``, of which aacmm_pin knows nothing. The script

1. simulates a campaign of the paper's model (DH and encoder errors, the sphere moving in its
   seat; 4 R-Test locations x 50 SPAT samples, a bar at 2 placements) whose base warms from 20 to
   26 deg C and whose A1 reads off by 3 arcsec per kelvin of it (hidden: not in the library), and
   writes its CSVs with the ``temp_base_c`` column in ``spat.csv`` and ``lengthbar.csv``;
2. installs the plugin as pip does, offline: its ``.dist-info`` (``METADATA``, the entry points of
   ``pyproject.toml``) and its module in ``OUT/site``, on the ``PYTHONPATH`` of the commands it
   runs (``pip install examples/05_plugin`` installs it in your environment the same way);
3. runs ``aacmm-pin discover`` in a fresh process: it names ``basetemp`` on A1 and the held-out
   gap shrinks; ``parameters.json`` names the plugin (``"plugins": {"aacmm-pin-basetemp":
   ["basetemp[A1]"]}``);
4. runs ``aacmm-pin predict`` and ``aacmm-pin validate`` on that calibration in fresh processes,
   which apply the term (and ``predict`` without the plugin, which says which plugin is missing).

Exits with status 1 if discovery does not name the effect, the gap does not shrink, or a command
fails. Run: ``python examples/05_plugin.py [--out examples/out/plugin-example]`` (about 6 s).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from aacmm_pin import SimulationConfig, load_arm, simulate_campaign, write_campaign

PLUGIN = Path(__file__).resolve().parent / "05_plugin"
COLUMN = "temp_base_c"

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "plugin-example"),
                    help="output folder (default: examples/out/plugin-example)")
parser.add_argument("--arcsec-per-k", type=float, default=3.0,
                    help="the hidden A1 error per kelvin of base temperature, arcsec/K")
parser.add_argument("--seed", type=int, default=0, help="seed of the simulated campaign")
args = parser.parse_args()
out = Path(args.out)
WRITES = {"campaign", "site", "discovery", "points.csv", "x.csv"}
"""What the script writes in ``--out``: a folder holding only these is its own earlier run."""
if out.exists():
    foreign = sorted(p.name for p in out.iterdir() if p.name not in WRITES)
    if foreign:  # never delete what this script did not write
        sys.exit(f"{out} holds {', '.join(foreign[:3])}{' ...' if len(foreign) > 3 else ''}, "
                 "which this example did not write: choose another --out")
    shutil.rmtree(out)


# 1. a campaign with the hidden effect: A1 reads theta_true - c (T_base - 20 C)
def base_temperature(n: int, rng: np.random.Generator) -> np.ndarray:
    """The base warms from 20 to 26 deg C over the campaign (time order), +-0.05 deg C noise."""
    return 20.0 + 6.0 * (1.0 - np.exp(-np.arange(n) / (n / 2))) + rng.normal(0.0, 0.05, n)


arm = load_arm()
sim = simulate_campaign(arm, SimulationConfig(seed=args.seed, effects=("dh", "encoder", "rtest"),
                                              samples_per_location=50, bar_placements=2,
                                              samples_per_socket=10))
campaign = sim.campaign
assert campaign.spat is not None and campaign.lengthbar is not None
rng = np.random.default_rng(args.seed)
n_spat, n_bar = len(campaign.spat.q), len(campaign.lengthbar.q)
temp = base_temperature(n_spat + n_bar, rng)  # the SPATs first, then the bar
c = np.radians(args.arcsec_per_k / 3600)
logs = {"spat.csv": campaign.spat, "lengthbar.csv": campaign.lengthbar}
cells = {"spat.csv": temp[:n_spat], "lengthbar.csv": temp[n_spat:]}
shifted = {}
for name, log in logs.items():
    q = np.array(log.q)
    q[:, 0] -= c * (cells[name] - 20.0)
    shifted[name] = replace(log, q=q)
campaign = replace(campaign, spat=shifted["spat.csv"], lengthbar=shifted["lengthbar.csv"])
folder = out / "campaign"
write_campaign(campaign, folder)
for name, values in cells.items():  # the column the package has never heard of
    lines = (folder / name).read_text().splitlines()
    rows = [f"{lines[0]},{COLUMN}"] + [f"{line},{v:.3f}" for line, v in zip(lines[1:], values)]
    (folder / name).write_text("\n".join(rows) + "\n")
print(f"simulated {n_spat} SPAT samples and {n_bar} bar readouts; base {temp.min():.1f} -> "
      f"{temp.max():.1f} deg C, A1 off by {args.arcsec_per_k:g} arcsec/K (hidden) -> {folder}")


# 2. install the plugin as pip does: a dist-info naming the entry points, beside the module
def pyproject_strings(path: Path) -> dict[str, dict[str, str]]:
    """Return table -> key -> string value of a pyproject.toml's ``key = "value"`` lines.

    (What ``tomllib`` gives on Python >= 3.11, for the string entries this example needs.)
    """
    tables: dict[str, dict[str, str]] = {}
    table = ""
    for line in path.read_text().splitlines():
        line = line.strip()
        if line.startswith("[") and line.endswith("]"):
            table = line.strip("[]").replace('"', "")
        elif "=" in line and not line.startswith("#"):
            key, value = (part.strip() for part in line.split("=", 1))
            if value.startswith('"') and value.endswith('"'):
                tables.setdefault(table, {})[key.strip('"')] = value.strip('"')
    return tables


def install(plugin: Path, site: Path) -> str:
    """Install the distribution of ``plugin``'s pyproject.toml into ``site``; return its name."""
    tables = pyproject_strings(plugin / "pyproject.toml")
    name, version = tables["project"]["name"], tables["project"]["version"]
    info = site / f"{name.replace('-', '_')}-{version}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    groups = {t.removeprefix("project.entry-points."): entries for t, entries in tables.items()
              if t.startswith("project.entry-points.")}
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in entries.items()) + "\n"
        for group, entries in groups.items()))
    for module in plugin.glob("*.py"):
        shutil.copy(module, site / module.name)
    return str(name)


site = out / "site"
plugin = install(PLUGIN, site)
print(f"installed the plugin {plugin} in {site} (entry point group aacmm_pin.effects)")
with_plugin = {**os.environ, "PYTHONPATH": os.pathsep.join(
    [str(site.resolve()), *filter(None, [os.environ.get("PYTHONPATH")])])}


def aacmm_pin(*argv: str, env: dict[str, str] | None = None, check: bool = True
              ) -> subprocess.CompletedProcess[str]:
    """Run ``aacmm-pin ARGV`` in a fresh process (with the plugin unless ``env`` says otherwise)."""
    done = subprocess.run([sys.executable, "-m", "aacmm_pin", *argv], capture_output=True,
                          text=True, env=env or with_plugin)
    if check and done.returncode != 0:
        sys.exit(f"aacmm-pin {argv[0]} failed:\n{done.stderr}")
    return done


# 3. discovery names the plugin's effect
disc = out / "discovery"
aacmm_pin("discover", str(folder), "--start", "proposed", "--out", str(disc))
report = json.loads((disc / "discovery.json").read_text())
params = json.loads((disc / "parameters.json").read_text())
steps = report["steps"]
for k, step in enumerate(steps, start=1):
    print(f"discover step {k}: {step['effect']} on {', '.join(f'A{a}' for a in step['axes'])}: "
          f"held-out RMS {step['heldout_rms_before_um']:.2f} -> {step['heldout_rms_after_um']:.2f} "
          f"um")
found = params.get("extensions", {}).get("basetemp[A1]")
if found is not None:
    print(f"  basetemp[A1]: identified {np.degrees(found[0]) * 3600:.2f} arcsec/K, true "
          f"{args.arcsec_per_k:g}; parameters.json plugins: {params.get('plugins')}")

# 4. predict and validate apply it in fresh processes; without the plugin, predict says so
readouts = folder / "spat.csv"
aacmm_pin("predict", str(disc), str(readouts), "--out", str(out / "points.csv"))
points = np.loadtxt(out / "points.csv", delimiter=",", skiprows=1)[:, -3:]
print(f"predict: {len(points)} stylus centres -> {out / 'points.csv'}")
bare = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", "")}
missing = aacmm_pin("predict", str(disc), str(readouts), "--out", str(out / "x.csv"), env=bare,
                    check=False)
error = [line for line in missing.stderr.splitlines() if ": error: " in line]
print(f"predict without the plugin: {error[0] if error else missing.stderr.strip()}")
validation = aacmm_pin("validate", str(disc), str(folder)).stdout.strip().splitlines()
print("validate: " + next((line.strip() for line in validation if "RMS" in line), validation[-1]))

named = bool(steps) and steps[0]["effect"] == "basetemp" and steps[0]["axes"] == [1]
shrinks = named and steps[0]["heldout_rms_after_um"] < steps[0]["heldout_rms_before_um"]
ok = (named and shrinks and params.get("plugins") == {plugin: ["basetemp[A1]"]}
      and missing.returncode == 2 and plugin in missing.stderr)
print(f"wrote {out}")
sys.exit(0 if ok else 1)
