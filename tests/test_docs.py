"""The documentation in ``docs/`` against the code it documents.

* ``docs/case-file.md``: every ``Keys:`` line (one per table section) lists exactly the keys the
  parser of that table accepts (the constants in ``livesweep.config``,
  ``livesweep.stages.parametric``, ``livesweep.ident.state_space``,
  ``livesweep.stages.residual`` and ``livesweep.convert.table``).
* ``docs/outputs.md``: every ``/livesweep/<name>`` channel (and documented nested object) lists
  exactly the properties of its JSON Schema (``RESULT_SCHEMAS``); the ``report.json`` sections list
  every key a real report holds (the shipped XV-15 cruise case, identified here); the files of
  the report folder match.
* ``docs/method.md``: every "method.md §X.Y" the code cites (and every "method §X.Y" the other
  docs cite) is a heading there.
"""

from __future__ import annotations

import csv
import json
import re
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SRC = ROOT / "src" / "livesweep"

_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$")
_KEYS = re.compile(r"^Keys: (`[^`]+`(?:, `[^`]+`)*)$")
_COLUMNS = re.compile(r"^Columns: (`[^`]+`(?:, `[^`]+`)*)$")
_TICKED = re.compile(r"`([^`]+)`")


def _sections(path: Path) -> list[dict]:
    """The headings of a Markdown file in order, each with its level, text, the text of its
    level-2 ancestor and the ``Keys:`` / ``Columns:`` lines under it (fenced code ignored)."""
    out, h2, in_code = [], "", False
    current = {"level": 0, "text": "", "h2": "", "keys": [], "columns": [], "line": 0}
    out.append(current)
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            in_code = not in_code
            continue
        if in_code:
            continue
        m = _HEADING.match(line)
        if m:
            level, text = len(m.group(1)), m.group(2)
            if level <= 2:
                h2 = text
            current = {"level": level, "text": text, "h2": h2, "keys": [], "columns": [], "line": n}
            out.append(current)
            continue
        if line.startswith("Keys:"):
            k = _KEYS.match(line.rstrip())
            assert k, f"{path.name}:{n}: a Keys line must read exactly Keys: `a`, `b`, ...: {line!r}"
            current["keys"].append((n, _TICKED.findall(k.group(1))))
        if line.startswith("Columns:"):
            c = _COLUMNS.match(line.rstrip())
            assert c, f"{path.name}:{n}: a Columns line must read exactly Columns: `a`, `b`, ...: {line!r}"
            current["columns"].append((n, _TICKED.findall(c.group(1))))
    return out


def _one_keys_line(section: dict, where: str) -> list[str]:
    assert len(section["keys"]) == 1, (f"{where}: section {section['text']!r} (line {section['line']}) needs "
                                       f"exactly one Keys line, has {len(section['keys'])}")
    n, keys = section["keys"][0]
    assert len(keys) == len(set(keys)), f"{where}:{n}: a key is listed twice: {keys}"
    return keys


# ------------------------------------------------------------------------------------------------
# docs/case-file.md
# ------------------------------------------------------------------------------------------------

def _case_file_tables() -> dict[str, set]:
    """Heading text -> the keys the code accepts in that table."""
    from livesweep import config
    from livesweep.convert import table
    from livesweep.ident.state_space import _TABLE_KEYS
    from livesweep.stages import residual
    from livesweep.tf_tables import _TF_KEYS

    return {
        "Top-level tables of a case file": set(config.CASE_KEYS),
        "`[case]`": set(config._CASE_TABLE_KEYS),
        "`[[identify]]` and `[[verify]]`": set(config._RECORD_KEYS),
        "`[signals.<name>]`": set(config._SIGNAL_KEYS),
        "`[spectral]`": set(config._SPECTRAL_KEYS),
        "`[criteria]`": set(config.table_keys(config.Criteria)),
        "`[transfer_functions.<name>]`": set(_TF_KEYS),
        "`[state_space]`": set(_TABLE_KEYS),
        "`[state_space.parameters]`": {"value", "fixed"},     # per entry; checked below
        # min_evidence is in _KEYS only to be refused with a pointer to false_alarm (checked below)
        "`[residual]`": set(residual._KEYS) - {"min_evidence"},
        "Top-level tables of a channel map": set(config.MAP_KEYS),
        "`[map]`": set(config._MAP_TABLE_KEYS),
        "`[test_points]`": set(config._TEST_POINT_KEYS),
        "`[predictions.<name>]`": set(config.table_keys(config.Prediction)),
        "`[limits]`": set(config.table_keys(config.EnvelopeLimits)),
        "Top-level keys of a column map": set(table._MAP_KEYS),
        "`[columns.<name>]`": set(table._COLUMN_KEYS),
    }


def test_case_file_keys_match_the_parsers():
    path = DOCS / "case-file.md"
    expected = _case_file_tables()
    sections = _sections(path)
    seen = set()
    for s in sections:
        if not s["keys"]:
            continue
        assert s["text"] in expected, (f"case-file.md:{s['keys'][0][0]}: a Keys line under {s['text']!r}, "
                                       f"which is none of the tables the test knows: {sorted(expected)}")
        keys = _one_keys_line(s, "case-file.md")
        assert set(keys) == expected[s["text"]], (
            f"case-file.md: {s['text']}: documented {sorted(keys)}, the code accepts "
            f"{sorted(expected[s['text']])} (missing {sorted(expected[s['text']] - set(keys))}, "
            f"extra {sorted(set(keys) - expected[s['text']])})")
        seen.add(s["text"])
    assert seen == set(expected), f"case-file.md has no Keys line for {sorted(set(expected) - seen)}"


def test_case_file_reference_tables_are_generated_from_the_settings():
    """docs/case-file.md's tables of [case], [[identify]], [spectral], [criteria] and [test_points]
    are what ``python -m livesweep.settings_schema`` writes from the settings dataclasses."""
    from livesweep.settings import DOCUMENTED_TABLES, regenerate_docs

    text = (DOCS / "case-file.md").read_text(encoding="utf-8")
    assert regenerate_docs(text) == text, "docs/case-file.md is stale: run python -m livesweep.settings"
    for name in DOCUMENTED_TABLES:
        assert f"<!-- settings: {name} -->" in text, name


def test_residual_min_evidence_is_refused_and_parameters_take_value_and_fixed():
    """The two key sets of test_case_file_keys_match_the_parsers that are not plain constants."""
    from livesweep.errors import ConfigError
    from livesweep.ident.state_space import StateSpaceModel
    from livesweep.stages.residual import residual_settings

    case = types.SimpleNamespace(path=Path("case.toml"), tables={"residual": {"min_evidence": 10.0}})
    with pytest.raises(ConfigError, match="min_evidence"):
        residual_settings(case)
    table = {"states": ["p"], "inputs": ["da"], "outputs": ["p"], "F": [["Lp"]], "G": [["Lda"]], "H": [["1"]],
             "parameters": {"Lp": {"value": -1.0, "fixed": False}, "Lda": {"value": 2.0, "fixed": True}}}
    assert StateSpaceModel.from_table(table).fixed == (False, True)
    table["parameters"]["Lp"]["bounds"] = [0, 1]
    with pytest.raises(ConfigError, match="value, fixed"):
        StateSpaceModel.from_table(table)


# ------------------------------------------------------------------------------------------------
# docs/method.md
# ------------------------------------------------------------------------------------------------

_NUM = r"\d+(?:\.\d+)?"
_REF = rf"§\s*{_NUM}(?:\s*[-–]\s*{_NUM})?"
_CITE = re.compile(rf"method\.md`{{0,2}}\s*({_REF}(?:\s*(?:,|and)\s*{_REF})*)")
_DOC_CITE = re.compile(rf"method(?:\.md)?\]?(?:\([^)]*\))?\s*({_REF}(?:\s*(?:,|and)\s*{_REF})*)")
_ONE_REF = re.compile(rf"§\s*({_NUM})(?:\s*[-–]\s*({_NUM}))?")
_METHOD_HEADING = re.compile(r"^#{1,6}\s+§(\d+(?:\.\d+)*)(?![\d.])")


def _expand(group: str) -> set[str]:
    """Section numbers of a citation group: ``§3.2-3.4`` -> 3.2, 3.3, 3.4; ``§0, §4.3`` -> 0, 4.3."""
    out = set()
    for a, b in _ONE_REF.findall(group):
        out.add(a)
        if b:
            (ma, _, na), (mb, _, nb) = a.partition("."), b.partition(".")
            if ma == mb and na and nb:
                out.update(f"{ma}.{k}" for k in range(int(na), int(nb) + 1))
            else:
                out.add(b)
    return out


def _method_headings() -> list[str]:
    return [m.group(1) for line in (DOCS / "method.md").read_text(encoding="utf-8").splitlines()
            if (m := _METHOD_HEADING.match(line))]


def test_method_sections_are_numbered_like_the_reference():
    heads = _method_headings()
    assert len(heads) == len(set(heads)), f"method.md: a section number is used twice: {heads}"
    wanted = {str(k) for k in range(0, 14)}
    wanted |= {f"{a}.{b}" for a, n in ((1, 3), (2, 5), (3, 5), (4, 6), (6, 2), (7, 3), (8, 5), (11, 4))
               for b in range(1, n + 1)}
    assert wanted <= set(heads), f"method.md lacks sections {sorted(wanted - set(heads))}"


def test_every_method_citation_in_the_code_resolves():
    heads = set(_method_headings())
    cited: dict[str, list[str]] = {}
    for py in sorted(SRC.rglob("*.py")):
        text = py.read_text(encoding="utf-8")
        for m in _CITE.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            for sec in _expand(m.group(1)):
                cited.setdefault(sec, []).append(f"{py.relative_to(ROOT)}:{line}")
    assert len(cited) >= 20, f"found only {sorted(cited)}: is the citation pattern still right?"
    missing = {sec: where for sec, where in cited.items() if sec not in heads}
    assert not missing, f"docs/method.md has no heading for {missing}"


def test_every_method_citation_in_the_docs_resolves():
    heads = set(_method_headings())
    bad = []
    for md in sorted(DOCS.glob("*.md")):
        for n, line in enumerate(md.read_text(encoding="utf-8").splitlines(), 1):
            for m in _DOC_CITE.finditer(line):
                bad += [f"{md.name}:{n}: §{s}" for s in _expand(m.group(1)) if s not in heads]
    assert not bad, "citations of method.md sections that do not exist: " + "; ".join(bad)


# ------------------------------------------------------------------------------------------------
# docs/outputs.md: the /livesweep channels
# ------------------------------------------------------------------------------------------------

def _schema_at(schema: dict, path: list[str]) -> dict:
    for seg in path:
        field, is_list = (seg[:-2], True) if seg.endswith("[]") else (seg, False)
        schema = schema["properties"][field]
        if is_list:
            schema = schema["items"]
    return schema


def test_livesweep_channels_match_their_schemas():
    from livesweep.telemetry.recorder import RESULT_SCHEMAS

    documented = set()
    for s in _sections(DOCS / "outputs.md"):
        ticked = _TICKED.findall(s["text"])
        if not ticked or not ticked[0].startswith("/livesweep/"):
            continue
        name, *path = ticked[0][len("/livesweep/"):].split(".")
        assert name in RESULT_SCHEMAS, f"outputs.md documents /livesweep/{name}, which the recorder does not write"
        keys = _one_keys_line(s, "outputs.md")
        try:
            schema = _schema_at(RESULT_SCHEMAS[name], path)
        except KeyError:
            pytest.fail(f"outputs.md: {ticked[0]} is not an object of the /livesweep/{name} schema")
        props = set(schema["properties"])
        assert set(keys) == props, (f"outputs.md: {ticked[0]}: documented {sorted(keys)}, schema {sorted(props)} "
                                    f"(missing {sorted(props - set(keys))}, extra {sorted(set(keys) - props)})")
        if not path:
            documented.add(name)
    assert documented == set(RESULT_SCHEMAS), f"outputs.md does not document {sorted(set(RESULT_SCHEMAS) - documented)}"


# ------------------------------------------------------------------------------------------------
# docs/outputs.md: report.json and the report folder, against a real report
# ------------------------------------------------------------------------------------------------

#: Documented objects the cruise case's report does not hold (it adds no effect, tries none, and
#: its logs hold no live monitor's models: tests/test_live_models_report.py checks those on a
#: replayed recording).
LIVE_MODEL_OBJECTS = {"live_models[]", "live_models[].test_point", "live_models[].pairs[]",
                      "live_models[].pairs[].parameters[]", "live_models[].pairs[].figures[]",
                      "live_models[].pairs[].limits[]", "live_models[].pairs[].comparison",
                      "live_models[].pairs[].comparison.parameters[]"}
_ABSENT_IN_CRUISE = {"residual_loop.steps[].effect", "residual_loop.steps[].effect.significance",
                     "residual_loop.steps[].tried[]", *LIVE_MODEL_OBJECTS}


@pytest.fixture(scope="module")
def cruise_report(tmp_path_factory):
    import livesweep

    out = tmp_path_factory.mktemp("cruise_report")
    ident = livesweep.identify(ROOT / "config" / "xv15_cruise_lateral.toml")
    livesweep.write_report(ident, out, plots=False)
    return out


def _objects_at(obj, path: str) -> list[dict]:
    """The dicts at a documented path: ``a.b[]`` (every element), ``a.<signal>`` (every value)."""
    found = [obj]
    for seg in (path.split(".") if path else []):
        nxt = []
        name, is_list = (seg[:-2], True) if seg.endswith("[]") else (seg, False)
        for o in found:
            if not isinstance(o, dict):
                continue
            vals = list(o.values()) if name.startswith("<") else ([o[name]] if name in o else [])
            for v in vals:
                if is_list:
                    nxt += list(v) if isinstance(v, list) else []
                else:
                    nxt.append(v)
        found = nxt
    return [o for o in found if isinstance(o, dict)]


@pytest.mark.slow
def test_report_json_keys_are_documented(cruise_report):
    report = json.loads((cruise_report / "report.json").read_text())
    checked = set()
    for s in _sections(DOCS / "outputs.md"):
        if s["h2"] != "`report.json`" or s["level"] < 3 or not s["keys"]:
            continue
        keys = set(_one_keys_line(s, "outputs.md"))
        if s["text"] == "Top level of report.json":
            path = ""
        else:
            ticked = _TICKED.findall(s["text"])
            assert ticked, f"outputs.md:{s['line']}: a report.json section heading names its path in backticks"
            path = ticked[0]
        objs = _objects_at(report, path)
        if not objs:
            assert path in _ABSENT_IN_CRUISE, f"outputs.md documents report.json {path!r}, not in the cruise report"
            continue
        actual = set().union(*(o.keys() for o in objs))
        assert actual <= keys, (f"outputs.md: report.json {path or 'top level'} does not document "
                                f"{sorted(actual - keys)}")
        if path == "":
            assert keys == actual, f"outputs.md: report.json top level documents {sorted(keys - actual)} too"
        checked.add(path)
    for must in ("", "case", "frequency_responses[]", "data_quality", "transfer_functions[]", "state_space",
                 "state_space.parameters[]", "verification", "residual_loop", "residual_loop.steps[]"):
        assert must in checked, f"outputs.md has no Keys line for report.json {must or 'top level'}"


@pytest.mark.slow
def test_report_folder_files_are_documented(cruise_report):
    sections = {s["text"]: s for s in _sections(DOCS / "outputs.md")}
    frs = json.loads((cruise_report / "frequency_response_set.json").read_text())
    keys = _one_keys_line(sections["`frequency_response_set.json`"], "outputs.md")
    assert set(keys) == set(frs), f"frequency_response_set.json holds {sorted(frs)}, documented {sorted(keys)}"
    with open(cruise_report / "frequency_responses.csv", newline="") as f:
        header = next(csv.reader(f))
    (col_line,) = sections["`frequency_responses.csv` and `frequency_responses.mat`"]["columns"]
    assert col_line[1] == header, f"frequency_responses.csv columns are {header}, documented {col_line[1]}"
    table = (DOCS / "outputs.md").read_text(encoding="utf-8")
    for f in sorted(p.name for p in cruise_report.iterdir() if p.is_file()):
        assert f"`{f}`" in table, f"outputs.md does not mention the report file {f}"


# ------------------------------------------------------------------------------------------------
# links between the docs
# ------------------------------------------------------------------------------------------------

_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _anchors(path: Path) -> set[str]:
    """GitHub's heading anchors of a Markdown file (lower case, punctuation dropped, spaces to -,
    repeats numbered)."""
    out, in_code = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.lstrip().startswith("```"):
            in_code = not in_code
        m = None if in_code else _HEADING.match(line)
        if m:
            slug = re.sub(r"[^\w\- ]", "", m.group(2).replace("`", "").lower()).replace(" ", "-")
            n = sum(1 for s in out if s == slug or re.fullmatch(re.escape(slug) + r"-\d+", s))
            out.append(slug if n == 0 else f"{slug}-{n}")
    return set(out)


def test_links_between_the_docs_resolve():
    bad = []
    for md in sorted(DOCS.glob("*.md")):
        for n, line in enumerate(md.read_text(encoding="utf-8").splitlines(), 1):
            for target in _LINK.findall(line):
                if re.match(r"[a-z]+://", target):
                    continue
                file, _, anchor = target.partition("#")
                path = (md.parent / file).resolve() if file else md
                if not path.exists():
                    bad.append(f"{md.name}:{n}: {target} (no such file)")
                elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
                    bad.append(f"{md.name}:{n}: {target} (no such heading)")
    assert not bad, "broken links: " + "; ".join(bad)
