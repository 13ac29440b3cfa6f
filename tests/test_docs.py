"""The user-facing documents (README.md, docs/*.md) hold together: the README stays short, every
relative link and anchor resolves, no project history leaks into them, and the README's command
synopsis, error table and the settings table cover what the code has.

(The README's quick start is run against a real server by tests/integration/test_readme.py.)"""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
#: most lines the README may have: it speaks to users; measurements and design live in docs/
README_MAX_LINES = 320
#: sources whose error codes the README's table must list
SOURCES = ("solver", "hairport", "service", "worker")
#: a Markdown link or image: [text](target) / ![alt](target)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def user_documents() -> list[Path]:
    return [README, *DOCS]


def prose(path: Path) -> str:
    """The document without its fenced code blocks (a shell snippet holds no links)."""
    return FENCE.sub("", path.read_text())


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    found = set()
    for heading in re.findall(r"^#{1,6} (.+)$", prose(path), re.M):
        base = slug(heading)
        count = seen.get(base, 0)
        seen[base] = count + 1
        found.add(base if count == 0 else f"{base}-{count}")
    return found


def section(text: str, heading: str) -> str:
    """The text of the ``## heading`` section, up to the next ``## `` heading."""
    start = text.index(f"\n## {heading}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end > 0 else None]


def test_the_readme_is_short():
    assert len(README.read_text().splitlines()) <= README_MAX_LINES


def test_every_relative_link_and_anchor_resolves():
    broken, checked = [], 0
    for path in user_documents():
        for target in LINK.findall(prose(path)):
            if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            resolved = (path.parent / file).resolve() if file else path
            checked += 1
            if not resolved.exists() or ROOT not in (resolved, *resolved.parents):
                broken.append(f"{path.name}: {target}")
            elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
                broken.append(f"{path.name}: {target} (no such heading)")
    assert broken == []
    assert checked >= 50


def test_no_issue_numbers_or_commit_hashes():
    history = re.compile(r"\bissues?\s+#?\d+|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b", re.I)
    found = [f"{path.name}: {match.group(0)}" for path in user_documents()
             for match in history.finditer(path.read_text())]
    assert found == []


def test_the_history_pattern_sees_what_it_must():
    # the pattern of the test above, on text that must fail it and text that must pass it
    history = re.compile(r"\bissues?\s+#?\d+|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b", re.I)
    assert [m.group(0) for m in history.finditer("as issue 16 asks, at 27761c1, Issue #3")] == [
        "issue 16", "27761c1", "Issue #3"]
    assert history.search("10^7 particles, 1,000,000 points, 4e-16 m, beefed up, 0.0059 rad") is None


def synopsis_rows() -> tuple[dict[str, str], dict[str, str]]:
    """The README's command table (``hairport NAME`` -> its row) and option groups (``FRAME`` -> text)."""
    text = section(README.read_text(), "Command line")
    rows = {name: line for line, name in re.findall(r"^(\| `hairport ([a-z ]+)` \|.*)$", text, re.M)}
    groups = {name: line for line, name in re.findall(r"^(\* `([A-Z]+)`:.*(?:\n  .*)*)", text, re.M)}
    return rows, groups


def commands():
    """(name, parser) of every command of the command line, ``assets fetch`` included."""
    import argparse

    from hairport.cli import build_parser

    def walk(parser, prefix):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    yield from walk(child, f"{prefix} {name}".strip())
                return
        yield prefix, parser

    return list(walk(build_parser(), ""))


def test_the_synopsis_names_every_command_and_option():
    rows, groups = synopsis_rows()
    missing, checked = [], 0
    for name, parser in commands():
        if name not in rows:
            missing.append(name)
            continue
        text = rows[name] + "".join(groups[group] for group in groups if f"`{group}`" in rows[name])
        for action in parser._actions:
            for option in action.option_strings:
                if option in ("-h", "--help"):
                    continue
                checked += 1
                if not re.search(re.escape(option) + r"(?![\w-])", text):
                    missing.append(f"{name} {option}")
    assert missing == []
    assert len(rows) == len(commands()) and checked >= 90


def code_strings(node: ast.AST, constants: dict[str, str]) -> list[str]:
    """The codes an expression passed as a ``code`` can be: a literal, a named constant, or either
    branch of ``a or b`` / ``a if c else b`` (not a value read from a mapping)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.Name):
        return [constants[node.id]] if node.id in constants else []
    if isinstance(node, ast.BoolOp):
        return [code for value in node.values for code in code_strings(value, constants)]
    if isinstance(node, ast.IfExp):
        return code_strings(node.body, constants) + code_strings(node.orelse, constants)
    return []


#: callables that take an error code, and the position of the code among their arguments
CODE_ARGUMENT = {"InputError": 2, "error": 1, "_error": 1, "parse_json": 2, "Problem": 1, "problem_response": 1}


def codes_in_the_code() -> set[str]:
    """Every error code the command line, the API and the workers can answer, read from the sources."""
    from hairport.service.errors import PROBLEM_STATUSES
    from hairport.solver.io.hair.common import ERROR_CODES

    trees = [ast.parse(path.read_text()) for top in SOURCES for path in sorted((ROOT / top).rglob("*.py"))]
    constants = {target.id: node.value.value for tree in trees for node in ast.walk(tree)
                 if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
                 and isinstance(node.value.value, str)
                 for target in node.targets if isinstance(target, ast.Name) and target.id.isupper()}
    codes = set(ERROR_CODES) | {code for _, listed in PROBLEM_STATUSES.values() for code in listed}
    for tree in trees:
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
                passed = [keyword.value for keyword in node.keywords if keyword.arg == "code"]
                if name in CODE_ARGUMENT and len(node.args) > CODE_ARGUMENT[name]:
                    passed.append(node.args[CODE_ARGUMENT[name]])
                codes.update(code for value in passed for code in code_strings(value, constants))
            elif isinstance(node, ast.FunctionDef):  # a default code (InputError's invalid_input)
                arguments = node.args.args[len(node.args.args) - len(node.args.defaults):]
                codes.update(code for argument, default in zip(arguments, node.args.defaults)
                             if argument.arg == "code" for code in code_strings(default, constants))
    return {code for code in codes if re.fullmatch(r"[a-z]+(_[a-z0-9]+)*", code)}


def error_table() -> dict[str, str]:
    """The README's error table: code -> its HTTP column."""
    table = {}
    for line in section(README.read_text(), "Error codes").splitlines():
        cells = [cell.strip() for cell in line.strip("|").split("|")] if line.startswith("| `") else []
        for code in re.findall(r"`([a-z_0-9]+)`", cells[0] if cells else ""):
            assert code not in table, f"{code} is listed twice"
            table[code] = cells[1]
    return table


def test_the_error_table_lists_every_code_the_code_can_answer():
    codes = codes_in_the_code()
    assert {"penetration_remaining", "worker_lost", "message_lost", "internal", "empty_hair", "invalid_input"} <= codes
    assert sorted(codes - set(error_table())) == []


def test_the_error_table_gives_each_api_code_its_status():
    from hairport.service.errors import PROBLEM_STATUSES

    table = error_table()
    wrong = [(status, code, table.get(code)) for status, (_, codes) in PROBLEM_STATUSES.items() for code in codes
             if str(status) not in (table.get(code) or "")]
    assert wrong == []


def test_the_settings_table_lists_every_setting():
    from hairport.settings import Settings

    text = (ROOT / "docs" / "operations.md").read_text()
    rows = set(re.findall(r"^\| `(HAIRPORT_[A-Z0-9_]+)` \|", section(text, "Settings"), re.M))
    assert rows == {f"HAIRPORT_{name.upper()}" for name in Settings.model_fields}
