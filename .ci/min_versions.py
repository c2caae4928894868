"""Print pip constraints that pin every declared floor of pyproject.toml (``pkg>=X`` -> ``pkg==X``).

Used by ``.ci/run`` to install the minimum versions the project declares in a second environment
and run the default tests there. ``jaxlib`` follows ``jax`` (jax needs a jaxlib of its own version).
Standard library only.
"""

import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def floors(extras=("test",)) -> dict[str, str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = list(project["dependencies"])
    for extra in extras:
        reqs += project.get("optional-dependencies", {}).get(extra, [])
    out = {}
    for req in reqs:
        m = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)\s*(>=|==)\s*([0-9][0-9A-Za-z.]*)\s*", req)
        if not m:
            sys.exit(f"min_versions: cannot read a floor from {req!r} (use 'pkg>=X' or 'pkg==X')")
        out[m.group(1).lower()] = m.group(3)
    if "jax" in out:
        out.setdefault("jaxlib", out["jax"])
    return out


if __name__ == "__main__":
    for name, version in floors().items():
        print(f"{name}=={version}")
