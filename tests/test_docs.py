"""The documentation keeps up with the code: README, site navigation, API and CLI references.

The site itself is built by ``tox -e docs`` (``mkdocs build --strict``); these checks need
no mkdocs and run in the default suite.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import itertools
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README_LIMIT = 15_000
INSTALL_AND_TRIAL = (
    "python3 -m venv .venv && .venv/bin/pip install -e . --config-settings editable_mode=compat"
    " && .venv/bin/symfuse trial"
)


def _hooks():
    spec = importlib.util.spec_from_file_location(
        "symfuse_docs_hooks", DOCS / "hooks" / "symfuse_docs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _ci_commands() -> list[str]:
    """The commands .ci/run runs (every line but comments, ``set`` and ``cd``)."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    return [
        line.strip()
        for line in lines
        if line.strip() and not line.lstrip().startswith(("#", "set ", "cd "))
    ]


def test_readme_is_a_short_welcome_carrying_the_commands_ci_runs():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme) < README_LIMIT
    commands = _ci_commands()
    assert commands, ".ci/run runs nothing"
    for command in [*commands, INSTALL_AND_TRIAL]:
        assert command in readme, command


def _nav_pages() -> list[str]:
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text.split("\nnav:\n", 1)[1].split("\n\n", 1)[0]
    return re.findall(r":\s*(\S+\.md)\s*$", nav, flags=re.MULTILINE)


def test_site_navigation_lists_every_page_and_only_pages_that_exist():
    nav = _nav_pages()
    pages = sorted(
        path.relative_to(DOCS).as_posix()
        for path in DOCS.rglob("*.md")
        if "hooks" not in path.relative_to(DOCS).parts
    )
    assert sorted(set(nav)) == pages
    assert len(nav) == len(set(nav)), "a page is listed twice"


def _attribute_docstring(module_name: str, name: str) -> str | None:
    """The string literal right after ``name = ...`` in a module's source, if any."""
    module = importlib.import_module(module_name)
    tree = ast.parse(inspect.getsource(module))
    body = tree.body
    for statement, following in itertools.pairwise(body):
        targets = (
            statement.targets
            if isinstance(statement, ast.Assign)
            else [statement.target]
            if isinstance(statement, ast.AnnAssign)
            else []
        )
        if any(isinstance(target, ast.Name) and target.id == name for target in targets):
            if isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant):
                return following.value.value if isinstance(following.value.value, str) else None
            return None
    return None


def _defining_module(name: str) -> str:
    """The module of ``pipeline.api`` whose source assigns ``name``."""
    api_source = inspect.getsource(importlib.import_module("pipeline.api"))
    for node in ast.parse(api_source).body:
        if isinstance(node, ast.ImportFrom) and any(alias.name == name for alias in node.names):
            return importlib.util.resolve_name("." * node.level + (node.module or ""), "pipeline")
    return "pipeline.api"


def test_every_public_api_name_has_a_docstring_for_the_reference():
    from pipeline import api

    assert "::: pipeline.api" in (DOCS / "reference" / "api.md").read_text(encoding="utf-8")
    missing = []
    for name in api.__all__:
        value = getattr(api, name)
        if inspect.isclass(value) or inspect.isfunction(value) or hasattr(value, "__wrapped__"):
            doc = value.__doc__
        else:  # a constant, an alias or a marker: its docstring follows the assignment
            doc = _attribute_docstring(_defining_module(name), name)
        if not (doc and doc.strip()):
            missing.append(name)
    assert not missing, f"pipeline.api names without a docstring: {missing}"


def test_the_api_page_check_flags_a_name_the_rendered_page_lacks(caplog):
    hooks = _hooks()

    class Page:
        class file:
            src_uri = hooks.API_PAGE

    names = hooks.api_names()
    shown = "".join(f'<h2 id="pipeline.api.{name}">' for name in names[1:])
    with caplog.at_level("WARNING"):
        hooks.on_page_content(shown, Page, None, None)
    assert [record.getMessage() for record in caplog.records] == [
        f"{hooks.API_PAGE}: pipeline.api.{names[0]} is in __all__ but not on the page"
    ]


def test_every_theme_module_of_the_api_has_its_reference_page():
    hooks = _hooks()
    themes = sorted(
        path.stem
        for path in (ROOT / "pipeline" / "api").glob("*.py")
        if not path.stem.startswith("_")
    )
    assert sorted(hooks.API_THEMES) == themes
    for page, module in hooks.API_PAGES.items():
        assert f"::: {module}\n" in (DOCS / page).read_text(encoding="utf-8"), page


def test_a_theme_page_missing_a_name_of_its_module_is_flagged(caplog):
    hooks = _hooks()

    class Page:
        class file:
            src_uri = "reference/api-planning.md"

    names = hooks.api_names("pipeline.api.planning")
    assert "TopParallel" in names and "ParallelHand" in names
    shown = "".join(
        f'<h2 id="pipeline.api.planning.{name}">' for name in names if name != "hand_pose"
    )
    with caplog.at_level("WARNING"):
        hooks.on_page_content(shown, Page, None, None)
    assert [record.getMessage() for record in caplog.records] == [
        "reference/api-planning.md: pipeline.api.planning.hand_pose is in __all__ "
        "but not on the page"
    ]


def test_every_snippet_the_docs_include_exists_with_its_section():
    """``--8<--`` includes (pymdownx.snippets) show the examples' tested code: each names a
    file of the repository and, after a colon, a section marked in it (a missing section
    would be shown empty)."""
    pages = "\n".join(page.read_text(encoding="utf-8") for page in DOCS.glob("*.md"))
    includes = re.findall(r'--8<-- "([^"]+)"', pages)
    includes += re.findall(r"^--8<--\n(.+?)\n--8<--$", pages, flags=re.MULTILINE)
    assert len(includes) >= 3
    for include in includes:
        path, _, section = include.partition(":")
        text = (ROOT / path).read_text(encoding="utf-8")
        if section:
            assert f"--8<-- [start:{section}]" in text and f"--8<-- [end:{section}]" in text


def test_every_cli_option_has_help_and_is_in_the_cli_reference():
    hooks = _hooks()
    assert hooks.CLI_MARKER in (DOCS / "cli.md").read_text(encoding="utf-8")
    assert "docs/hooks/symfuse_docs.py" in (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    parser = hooks.cli_parser()
    reference = hooks.render_cli_reference(parser)
    sections = dict(
        (chunk.split("\n", 1)[0].strip(), chunk) for chunk in reference.split("## symfuse")[1:]
    )
    verbs = hooks.verbs(parser)
    assert {name for name, _ in verbs} >= {"trial", "fuse", "complete", "sweep", "view"}
    undocumented = []
    for name, sub in [("", parser), *verbs]:
        section = sections[name]
        for action in hooks.documented_actions(sub):
            if not hooks.help_text(sub, action):
                undocumented.append(f"symfuse {name} {'/'.join(action.option_strings)}")
            for option in action.option_strings or [action.metavar or action.dest]:
                assert f"`{option}`" in section, f"symfuse {name} {option}"
    assert not undocumented, f"options without help text: {undocumented}"


@pytest.mark.slow
def test_the_site_builds_with_every_link_checked(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    pytest.importorskip("material")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin"},
    )
    assert result.returncode == 0, result.stderr[-3000:]


def test_no_docstring_counts_its_own_lines():
    """A module's length goes stale with the next change; its docstring says what it holds."""
    pattern = re.compile(r"\b(about|some|over) [0-9,]+ lines\b")
    stale = [
        f"{path.relative_to(ROOT)}:{number}"
        for folder in ("pipeline", "plugins")
        for path in sorted((ROOT / folder).rglob("*.py"))
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not stale, stale
