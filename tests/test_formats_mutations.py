"""The controller-file readers and patchers on mutated copies of the corpus files: whatever a
file holds, the answer is a FormatError naming a line (a 422), never another exception (a
500). Seeded: the same 1000 mutations each run; two of them met ``PAYLOAD [ 1`` (a ValueError
in the FANUC reader) before it was fixed. A longer run: ``python
tests/test_formats_mutations.py SEED N`` (seeds 2, 3, 4: 6000, 12000, 12000 mutations, none)."""

from __future__ import annotations

import random
import sys
from dataclasses import replace
from pathlib import Path

from server.formats import abb, fanuc, fanuc_sysframe, kuka, ur
from solvers.errors import CalibrationError
from solvers.frames import Pose

CORPUS = Path(__file__).parent / "data" / "controller-files"
READERS = {".dat": kuka.read_kuka, ".mod": abb.read_abb, ".sys": abb.read_abb,
           ".txt": fanuc.read_fanuc, ".va": fanuc_sysframe.read_sysframe, ".script": ur.read_ur}
ODD = ["\x00", "\u0663", "\u2028", "\r", '"', "{", "}", "[", "]", ",", ";", "!", "=", ":", "\t",
       "e", ".", "-", "#", "'"]


def _text(p: Path) -> str:
    raw = p.read_bytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("cp1252")


def _mutate(s: str, r: random.Random) -> str:
    """One of the traits a damaged or hand-edited file has: cut short, a long digit run, an odd
    character, a character or a line gone or doubled, a stretch repeated, digits replaced."""
    i = r.randrange(len(s))
    lines = s.split("\n")
    k = r.randrange(len(lines))
    return r.choice([
        lambda: s[:i],
        lambda: s[:i] + "9" * r.choice([5, 400, 5000]) + s[i:],
        lambda: s[:i] + r.choice(ODD) + s[i:],
        lambda: s[:i] + s[i + 1:],
        lambda: "\n".join(lines[:k] + [lines[k]] + lines[k:]),
        lambda: "\n".join(lines[:k] + lines[k + 1:]),
        lambda: s[:i] + s[i:i + 30] * r.choice([2, 50]) + s[i + 30:],
        lambda: s.replace(r.choice(["1", "0", ".", ",", " "]),
                          r.choice(["", "11", "..", ",,", "  ", "E", "\u0663"]), r.choice([1, 3])),
    ])()


def _read_and_patch(suffix: str, text: str) -> None:
    """Read ``text``; if it reads, patch a changed first entry back into it (the export)."""
    entries = list(READERS[suffix](text).entries)
    if entries:
        q = entries[0].pose
        entries[0] = replace(entries[0], pose=Pose(q.x + 0.5, q.y, q.z, q.a + 1.0, q.b, q.c))
    if suffix == ".dat":
        kuka.export_kuka(entries, template=text)
    elif suffix in (".mod", ".sys"):
        abb.export_abb(entries, template=text)
    elif suffix == ".va":
        fanuc_sysframe.patch_sysframe(entries, text)


def failures(seed: int, n: int) -> list[tuple[str, str, str]]:
    """(file, exception, message) of each mutated text that raised anything but a
    CalibrationError (FormatError is one)."""
    r = random.Random(seed)
    files = sorted(p for p in CORPUS.iterdir() if p.suffix in READERS)
    texts = {p: _text(p) for p in files}
    out = []
    for _ in range(n):
        p = r.choice(files)
        s = texts[p]
        for _ in range(r.choice([1, 1, 2, 3])):
            if s:
                s = _mutate(s, r)
        try:
            _read_and_patch(p.suffix, s)
        except CalibrationError:
            pass
        except Exception as err:  # noqa: BLE001  (what the test looks for)
            out.append((p.name, type(err).__name__, str(err)[:200]))
    return out


def test_mutated_controller_files_get_a_format_error_or_are_read():
    assert failures(seed=1, n=1000) == []


if __name__ == "__main__":
    found = failures(int(sys.argv[1]), int(sys.argv[2]))
    for f in found:
        print(*f)
    print(f"{len(found)} of {sys.argv[2]} raised something other than a FormatError")
