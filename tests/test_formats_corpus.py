"""The whole-file promise on the corpus (issue 23): for every controller file of
tests/data/controller-files, an import then an export with no change gives back the same
bytes (encoding, line endings, every character); after one tool's X and one base's A are
changed through the API, exactly those values' text differs, in the file's own encoding and
line endings, and the file reads back with those two changes and nothing else."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from api_helpers import C, ok
from server import formats

CORPUS = Path(__file__).parent / "data" / "controller-files"
FILES = sorted(p for p in CORPUS.iterdir() if p.suffix in (".dat", ".mod", ".sys"))
ABB_ARM = "abb_irb120"  # an ABB-kind controller: its tables hold what its modules declare
NUM = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def fmt_of(path: Path) -> str:
    return "kuka" if path.suffix == ".dat" else "abb"


def lines_with_ends(text: str) -> list[tuple[str, str]]:
    parts = re.split(r"(\r\n|\r|\n)", text)
    return list(zip(parts[0::2], parts[1::2] + [""]))


def changed_numbers(old: str, new: str) -> list[tuple[int, int, str, str]]:
    """(line, index of the number in its line, old text, new text) of every number whose text differs; the lines, their
    endings and everything between the numbers must be equal."""
    a, b = lines_with_ends(old), lines_with_ends(new)
    assert len(a) == len(b), "a line was added or removed"
    out = []
    for i, ((la, ea), (lb, eb)) in enumerate(zip(a, b), 1):
        assert ea == eb, f"line {i}: its ending changed from {ea!r} to {eb!r}"
        if la == lb:
            continue
        assert NUM.split(la) == NUM.split(lb), f"line {i}: more than numbers changed:\n{la}\n{lb}"
        out += [(i, j, x, y) for j, (x, y) in enumerate(zip(NUM.findall(la), NUM.findall(lb)))
                if x != y]
    return out


def line_of(lines: list[str], start: str) -> int:
    return next(i for i, s in enumerate(lines, 1) if start in s)


def name_of(text: str, e: formats.FrameEntry) -> str:
    """The RAPID name of an entry (the name, or the declaration after its pendant tag)."""
    tag = re.search(rf'! pendant: {e.kind} {e.number} "[^"]*"\s*\n\s*PERS \w+ (\w+)', text)
    return tag.group(1) if tag else e.name


def pick(entries: list[formats.FrameEntry]) -> tuple[formats.FrameEntry, formats.FrameEntry]:
    """The first tool and the first base-table slot with a frame (or the first of each)."""
    tools = [e for e in entries if e.kind in ("tool", "workpiece")]
    bases = [e for e in entries if e.kind not in ("tool", "workpiece")]
    return tools[0], bases[0]


def controller_for(client, fmt: str) -> str:  # noqa: ANN001
    """The demo KUKA cell for a KUKA file; a new ABB cell for a RAPID module."""
    if fmt == "kuka":
        return C
    cid = ok(client.post("/controllers", json={"name": "abb-cell", "robot": ABB_ARM}))["id"]
    return f"/controllers/{cid}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_corpus_file_comes_back_whole_with_only_the_change_asked_for(client, path):
    raw = path.read_bytes()
    fmt = fmt_of(path)
    C = controller_for(client, fmt)  # noqa: N806  (the controller's path, as elsewhere)
    text, encoding = formats.decode_file(raw)
    ok(client.post(f"{C}/import", json={"format": fmt, "text": text, "encoding": encoding}))
    r = client.get(f"{C}/export", params={"format": fmt})
    assert r.content == raw  # byte for byte: encoding, line endings, every character

    before = formats.READERS[fmt](text).entries
    if not before:  # a new robot's file, every slot unused: calibrate tool 1 and base 1
        tool = formats.FrameEntry(1, "", "tool", formats.model.Pose())
        base = formats.FrameEntry(1, "", "base", formats.model.Pose())
    else:
        tool, base = pick(before)
    t = ok(client.get(f"{C}/tools/{tool.number}"))["pose"]
    b = ok(client.get(f"{C}/bases/{base.number}"))["pose"]
    assert (t["x"], b["a"]) == (tool.pose.x, base.pose.a)  # full precision from the API
    ok(client.put(f"{C}/tools/{tool.number}", json={"pose": {"x": t["x"] + 1}}, headers={"If-Match": "*"}))
    ok(client.put(f"{C}/bases/{base.number}", json={"pose": {"a": b["a"] + 1}}, headers={"If-Match": "*"}))
    out = client.get(f"{C}/export", params={"format": fmt}).content
    new_text = out.decode(encoding, errors="pendant-c1") if encoding != "utf-8" else out.decode()
    if not before:  # the two slots become used: their TYPE is written (#NONE -> #BASE)
        text = text.replace("TOOL_TYPE[1]=#NONE", "TOOL_TYPE[1]=#BASE", 1)
        text = text.replace("BASE_TYPE[1]=#NONE", "BASE_TYPE[1]=#BASE", 1)
    changes = changed_numbers(text, new_text)
    lines = text.splitlines()
    if fmt == "kuka":  # exactly X of the tool and A of the base (numbers 1 and 4 after [n])
        assert [(i, j) for i, j, _, _ in changes] == [
            (line_of(lines, f"TOOL_DATA[{tool.number}]="), 1),
            (line_of(lines, f"BASE_DATA[{base.number}]="), 4)]
    else:  # the tool's x, then the orientation of the base's frame (up to 4 numbers)
        assert changes[0][0] == line_of(lines, f"PERS tooldata {name_of(text, tool)}")
        assert float(changes[0][3]) == float(changes[0][2]) + 1
        assert 1 <= len(changes) - 1 <= 4
        assert {i for i, _, _, _ in changes[1:]} == {line_of(lines, f"wobjdata {name_of(text, base)}")}
    after = {(e.kind, e.number): e for e in formats.READERS[fmt](new_text).entries}
    for e in before:
        got = after[(e.kind, e.number)]
        if e == tool:
            assert got.pose.x == pytest.approx(e.pose.x + 1, abs=1e-12)
            assert got.pose.as_array()[1:] == pytest.approx(e.pose.as_array()[1:], abs=1e-9)
        elif e == base:
            assert got.pose.a == pytest.approx(e.pose.a + 1, abs=1e-6)
        else:
            assert got == e


def test_a_kuka_kind_controller_keeps_16_tools_and_names_the_line_of_the_17th(client):
    """The 36-tool RobotWare backup imports whole into an ABB-kind controller (above); a
    KUKA-kind controller has 16 tool slots: refused, naming tool 17's line, nothing changed."""
    path = CORPUS / "abb_backup_36_tools.sys"
    text, encoding = formats.decode_file(path.read_bytes())
    before = client.get(f"{C}/export", params={"format": "json"}).json()["entries"]
    r = client.post(f"{C}/import", json={"format": "abb", "text": text, "encoding": encoding})
    assert r.status_code == 422, r.text
    (err,) = r.json()["detail"]
    tool17 = next(e for e in formats.READERS["abb"](text).entries
                  if e.kind == "tool" and e.number == 17)
    assert "tool 17" in err["msg"] and "16 tools" in err["msg"], err
    assert str(formats.READERS["abb"](text).slot_lines[("robot_held", 17)]) in str(err["loc"]), err
    assert tool17.number == 17
    assert client.get(f"{C}/export", params={"format": "json"}).json()["entries"] == before
