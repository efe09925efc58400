"""The README (and docs/findings.md) stay honest: commands parse, paths exist.

Cheap checks only, no job is run:

- every ``panel-deploy ...`` line in a fenced code block parses with
  :func:`panel_deploy.cli.build_parser` (real subcommand, accepted flags and
  values, required arguments present);
- every ``panel-deploy ...`` in an inline code span names a real subcommand
  and only flags that subcommand has (prose may quote a partial command);
- every repository path the documents mention exists (link targets relative
  to the document, paths in the text relative to the repository root), and
  neither points outside the repository (``../shared``, ``NOTES.md``);
- the pictures are committed and small.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from panel_deploy.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = [ROOT / "README.md", ROOT / "docs" / "findings.md", ROOT / "docs" / "formats.md"]

FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
INLINE = re.compile(r"`([^`]+)`")  # a span may run over a line break
LINK = re.compile(r"\]\(([^)\s]+)\)")
# A path-like token: word characters, dots and dashes joined by at least one slash.
PATH = re.compile(r"(?<![\w./~:+$-])((?:\.\./)*[\w.-]+(?:/[\w.-]+)+/?)")
EXTENSIONS = (".py", ".yaml", ".yml", ".md", ".mcap", ".png", ".xml", ".csv", ".npz", ".rrd",
              ".txt", ".cfg", ".toml", ".json")
#: The nodes' relative topic names, which look like paths into the package.
TOPICS = {"panel_deploy/model", "panel_deploy/panels", "panel_deploy/collision_events",
          "panel_deploy/collision_markers"}


def fenced_blocks(text: str) -> list[str]:
    return FENCE.findall(text)


def inline_spans(text: str) -> list[str]:
    return [" ".join(span.split()) for span in INLINE.findall(FENCE.sub("", text))]


def block_commands(text: str) -> list[list[str]]:
    """``panel-deploy`` command lines of the fenced blocks, comments dropped, split like a shell."""
    out = []
    for block in fenced_blocks(text):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip()
            if line.startswith("$ "):
                line = line[2:]
            if line.startswith("panel-deploy ") or line == "panel-deploy":
                out.append(shlex.split(line, comments=True))
    return out


def inline_commands(text: str) -> list[list[str]]:
    return [shlex.split(span) for span in inline_spans(text) if span.startswith("panel-deploy ")]


def parse_error(argv: list[str]) -> str | None:
    """None when ``panel-deploy ARGV[1:]`` parses, else the parser's complaint."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            build_parser().parse_args(argv[1:])
        except SystemExit as e:
            return err.getvalue().strip() or f"exit {e.code}"
    return None


def _subparsers(parser):
    for action in parser._actions:  # argparse keeps no public view of its subcommands
        if action.__class__.__name__ == "_SubParsersAction":
            return action.choices
    return {}


def flag_errors(argv: list[str]) -> list[str]:
    """Unknown subcommands and flags of a possibly partial ``panel-deploy`` command."""
    parser, words = build_parser(), argv[1:]
    while words and _subparsers(parser):
        choices = _subparsers(parser)
        if words[0] not in choices:
            return [f"{words[0]!r} is not a subcommand (choose from {', '.join(choices)})"]
        parser, words = choices[words[0]], words[1:]
    if _subparsers(parser):
        return ["subcommand missing"]
    known = {s for a in parser._actions for s in a.option_strings}
    return [f"{w.split('=')[0]!r} is not a flag of this subcommand" for w in words
            if w.startswith("-") and w.split("=")[0] not in known]


def path_errors(text: str, base: Path) -> list[str]:
    """Paths mentioned in TEXT that do not exist: link targets relative to BASE,
    other path-like tokens relative to the repository root when they start with
    one of its top-level entries or end with a file extension."""
    errors = []
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # URLs and anchors
        target = target.split("#")[0]
        if not (base / target).exists():
            errors.append(f"link {target} (from {base.relative_to(ROOT) or '.'})")
    top = {p.name for p in ROOT.iterdir()}
    for token in PATH.findall(LINK.sub("]", text)):
        token = token.rstrip(".")
        if token in TOPICS:
            continue
        first = token.split("/")[0]
        if first == "..":
            errors.append(f"{token} points outside the repository")
        elif (first in top or token.endswith(EXTENSIONS)) and not (ROOT / token).exists():
            errors.append(token)
    return errors


def _read(doc: Path) -> str:
    assert doc.exists(), f"{doc.relative_to(ROOT)} is missing"
    return doc.read_text(encoding="utf-8")


# --- the documents ------------------------------------------------------------------------

@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: p.name)
def test_every_command_in_a_code_block_parses(doc):
    commands = block_commands(_read(doc))
    if doc.name == "README.md":
        assert len(commands) >= 15, "the README's main jobs are missing"
    bad = [f"{shlex.join(c)}: {parse_error(c)}" for c in commands if parse_error(c)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: p.name)
def test_every_inline_command_uses_real_subcommands_and_flags(doc):
    bad = [f"{shlex.join(c)}: {e}" for c in inline_commands(_read(doc)) for e in flag_errors(c)]
    assert not bad, "\n".join(bad)


def test_the_readme_runs_every_main_job():
    jobs = {c[1] for c in block_commands(_read(ROOT / "README.md"))}
    assert jobs >= {"simulate", "run", "optimise", "replay", "collide", "fold", "export", "bench",
                    "schema"}


@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: p.name)
def test_every_path_mentioned_exists(doc):
    text = _read(doc)
    assert not path_errors(text, doc.parent), "\n".join(path_errors(text, doc.parent))
    assert "../shared" not in text and "NOTES.md" not in text, "points outside the repository"


def test_the_readme_pictures_are_committed_and_small():
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", _read(ROOT / "README.md"))
    assert {"docs/img/fold.png", "docs/img/strip.png"} <= set(pictures)
    for picture in pictures:
        assert (ROOT / picture).stat().st_size < 300_000, picture


def test_the_readme_stays_short():
    # A user document: the node suite's tables and the recording rules took it past 220.
    assert len(_read(ROOT / "README.md").splitlines()) <= 230


# --- the checks themselves catch what they are for -----------------------------------------

def test_a_wrong_command_is_caught():
    text = ("```bash\npanel-deploy simulate paper_4x4 --t-end 1   # fine\n"
            "panel-deploy simulate paper_4x4 --no-such-flag\n"
            "panel-deploy deploy paper_4x4\n"
            "panel-deploy optimise\n"
            "panel-deploy optimise paper_4x4 \\\n  --perturb many\n```\n")
    commands = block_commands(text)
    assert [c[1] for c in commands] == ["simulate", "simulate", "deploy", "optimise", "optimise"]
    assert parse_error(commands[0]) is None
    errors = [parse_error(c) for c in commands[1:]]
    assert all(errors), errors
    assert "--no-such-flag" in errors[0] and "deploy" in errors[1] and "many" in errors[3]


def test_a_wrong_inline_command_is_caught():
    text = ("Run `panel-deploy optimise paper_4x4\n  --max-evaluations 20` or "
            "`panel-deploy optimise --nope`, `panel-deploy bench work-precision --quick`, "
            "`panel-deploy bench sweep`, `panel-deploy deploy`.")
    found = {shlex.join(c): flag_errors(c) for c in inline_commands(text)}
    assert found["panel-deploy optimise paper_4x4 --max-evaluations 20"] == []
    assert found["panel-deploy bench work-precision --quick"] == []
    assert found["panel-deploy optimise --nope"] and found["panel-deploy bench sweep"]
    assert found["panel-deploy deploy"]


def test_a_missing_path_is_caught():
    text = ("See `bench/results/no_such_result.yaml`, [the notes](docs/nowhere.md), "
            "`elsewhere/data.csv`, ../shared/paper/ and `config/scenes/paper_4x4.yaml`; "
            "not paths: /joint_states, std_msgs/String, N m/rad, ~/deploy, "
            "[a site](https://example.org/x.md).")
    errors = path_errors(text, ROOT)
    assert any("no_such_result.yaml" in e for e in errors)
    assert any("docs/nowhere.md" in e for e in errors)
    assert any("elsewhere/data.csv" in e for e in errors)
    assert any("../shared" in e for e in errors)
    assert len(errors) == 4, errors
