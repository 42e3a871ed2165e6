"""The documents give no resource or speed figure of the present design by hand: they quote
``python -m mpu9250_ahrs report``, which prints them from Yosys and the simulator, so they
cannot drift from the code. Only the figures named in ``HISTORICAL`` may appear: past designs
and measured differences, stated as such."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", ROOT / "build" / "README.md",
        *sorted((ROOT / "hdl").glob("*.md")), *sorted((ROOT / "reference").glob("*.md"))]
FIGURE = re.compile(r"\d[\d,.]*\s*(?:LEs|logic elements|LUTs|M9Ks?|M9K blocks|flip-flops|"
                    r"multipliers? used|MHz Fmax|% of the device)")
HISTORICAL = {
    "first version's 3,731 LEs",          # the engine before its cost work, for comparison
    "130 LEs",                            # what a 2-bit-per-cycle divider would add
}


def test_no_hand_copied_resource_figures():
    found = []
    for path in DOCS:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for match in FIGURE.finditer(line):
                if not any(h in line and match.group(0) in h for h in HISTORICAL):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {match.group(0)!r}")
    assert not found, ("figures written by hand; quote `python -m mpu9250_ahrs report` "
                       "instead:\n" + "\n".join(found))
