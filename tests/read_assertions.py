"""List the assertions recorded by ``SC_ASSERTIONS=<file> ./dev test``, one value per line.

Usage: ``./dev python tests/read_assertions.py <file>.0`` prints, for every assertion that
holds a number, its source line and the values it compared in each parametrised case: the
margins of the test suite on this machine.
"""

import re
import sys
from pathlib import Path


def main(path: str) -> None:
    """Print each numerical assertion once, with the first line of every explanation."""
    seen: dict[tuple[str, int], tuple[str, list[tuple[str, str]]]] = {}
    for block in Path(path).read_text().split("@@ ")[1:]:
        head, _, explanation = block.partition("\n")
        match = re.match(r"(\S+?)::(\w+)(\[.*?\])?:(\d+): (.*)", head)
        if match is None:
            continue
        file, _, case, line, source = match.groups()
        entry = seen.setdefault((file, int(line)), (source, []))
        entry[1].append((case or "", explanation.split("\n")[0][:120]))
    for (file, line), (source, cases) in sorted(seen.items()):
        if re.search(r"\d", source):
            print(f"{Path(file).name}:{line} {source[:100]}")
            for case, value in cases:
                print(f"     {case[:30]:30s} {value}")


if __name__ == "__main__":
    main(sys.argv[1])
