"""Prints a pip constraints file that pins every dependency in pyproject.toml (runtime, dev and
every optional extra, such as events and notebook) to its lower bound, so the suite tests the
oldest versions chronocl claims (.ci/run's first run).

Usage: python3 .ci/lowest.py > lowest.txt; pip install -c lowest.txt -e '.[dev,events,notebook]'
"""

import re
import sys
import tomllib
from pathlib import Path

project = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())["project"]
extras = project["optional-dependencies"]
requirements = [*project["dependencies"], *(r for name in sorted(extras) for r in extras[name])]
for requirement in requirements:
    match = re.fullmatch(r"([A-Za-z0-9_.-]+)(\[[^\]]*\])?\s*(.*)", requirement)
    name, spec = match.group(1), match.group(3)
    lower = re.search(r">=\s*([^,\s]+)", spec)
    if lower is None:
        sys.exit(f"{requirement!r} has no lower bound (>=): give it one")
    print(f"{name}=={lower.group(1)}")
