#!/usr/bin/env bash
# The package as a user installs it: build a wheel from the tracked files, install it alone into a
# new virtual environment (the versions of constraints.txt, no extras), import every module of
# the installed package from outside the repository, and run two commands. CI runs this after
# `make test` (.ci/run); a module, a model file or a dependency that only the checkout provides
# fails here. About 1-2 minutes when pip's cache holds the dependencies.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# the tracked files only: a build writes build/ and *.egg-info beside its sources
mkdir "$tmp/src"
git ls-files -z | (cd "$root" && xargs -0 cp --parents -t "$tmp/src")
python=$("$root/tools/find_python312.sh")
"$python" -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install --quiet --upgrade pip -c "$root/constraints.txt"
"$tmp/venv/bin/python" -m pip wheel --quiet --no-deps -w "$tmp/dist" "$tmp/src" -c "$root/constraints.txt"
wheel=$(ls "$tmp"/dist/drake_abs-*.whl)
echo "built $(basename "$wheel")"
"$tmp/venv/bin/python" -m pip install --quiet "$wheel" -c "$root/constraints.txt"

cd "$tmp"  # away from the checkout: the imports must come from the installed wheel
"$tmp/venv/bin/python" - <<'EOF'
import importlib
import pkgutil
from pathlib import Path

import drake_abs

where = Path(drake_abs.__file__).resolve()
assert "site-packages" in where.parts, f"drake_abs imported from {where}, not the installed wheel"
names = ["drake_abs"] + [m.name for m in pkgutil.walk_packages(drake_abs.__path__, "drake_abs.")]
failed = {}
for name in names:
    try:
        importlib.import_module(name)
    except ModuleNotFoundError as err:  # an optional extra (mujoco, stable-baselines3, ray)
        if err.name and err.name.split(".")[0] in {"mujoco", "stable_baselines3", "sb3_contrib",
                                                    "torch", "ray"}:
            continue
        failed[name] = repr(err)
    except Exception as err:  # noqa: BLE001 (every failure is reported below)
        failed[name] = repr(err)
if failed:
    raise SystemExit("modules that do not import from the wheel:\n" + "\n".join(
        f"  {k}: {v}" for k, v in failed.items()))
print(f"imported {len(names)} modules from {where.parent}")
EOF
"$tmp/venv/bin/drake-abs" list >/dev/null
"$tmp/venv/bin/drake-abs" demo --duration 0.3 --no-meshcat --out "$tmp/demo" >/dev/null
test -s "$tmp/demo/summary.json"
echo "the installed wheel runs: drake-abs list, drake-abs demo"
