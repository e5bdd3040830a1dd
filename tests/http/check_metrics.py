"""Parses omnirow's /metrics (on stdin) with the Prometheus project's own text-format parser
(prometheus_client.parser) and checks what a scraper relies on: every sample belongs to a
family declared with # TYPE and # HELP, names are valid, values are numbers, no family or
sample repeats. Prints one line per family: NAME TYPE SAMPLES. Exits non-zero on a problem."""

import math
import re
import sys

from prometheus_client.parser import text_string_to_metric_families

text = sys.stdin.read()
problems = []
declared_types = {}
declared_help = set()
for line in text.splitlines():
    if line.startswith("# TYPE "):
        _, _, name, kind = line.split(" ", 3)
        # The parser names a counter's family without its `_total` suffix.
        if kind == "counter" and name.endswith("_total"):
            name = name[: -len("_total")]
        if name in declared_types:
            problems.append(f"# TYPE {name} twice")
        declared_types[name] = kind
    elif line.startswith("# HELP "):
        name = line.split(" ", 3)[2]
        declared_help.add(name[: -len("_total")] if name.endswith("_total") else name)
    elif line.startswith("#") or not line.strip():
        problems.append(f"unexpected line {line!r}")
if not text.endswith("\n"):
    problems.append("the exposition does not end with a newline")

NAME = re.compile(r"^[a-zA-Z_:][a-zA-Z0-9_:]*$")
seen = set()
families = list(text_string_to_metric_families(text))
for fam in families:
    if fam.name not in declared_types:
        problems.append(f"family {fam.name} has no # TYPE")
    elif declared_types[fam.name] != fam.type:
        problems.append(f"family {fam.name}: parsed as {fam.type}, declared {declared_types[fam.name]}")
    if fam.name not in declared_help:
        problems.append(f"family {fam.name} has no # HELP")
    if not fam.samples:
        problems.append(f"family {fam.name} has no sample")
    for s in fam.samples:
        if not NAME.match(s.name):
            problems.append(f"invalid name {s.name!r}")
        key = (s.name, tuple(sorted(s.labels.items())))
        if key in seen:
            problems.append(f"sample {key} twice")
        seen.add(key)
        if not isinstance(s.value, (int, float)) or (math.isinf(s.value) and fam.type == "counter"):
            problems.append(f"{s.name}: bad value {s.value!r}")
        if fam.type == "counter" and not (s.value >= 0):
            problems.append(f"{s.name}: negative or NaN counter {s.value}")
    print(fam.name, fam.type, len(fam.samples))

if set(declared_types) != {f.name for f in families}:
    problems.append(f"declared {sorted(declared_types)} but parsed {sorted(f.name for f in families)}")
for p in problems:
    print("PROBLEM:", p)
sys.exit(1 if problems else 0)
