"""mkdocs hooks that keep the site and the code together when the site is built.

* The command line reference (``cli.md``) is rendered from symfuse's own argparse parsers:
  the line ``<!-- symfuse-cli-reference -->`` becomes one section per verb with its usage,
  description and a table of its arguments, so the page cannot fall behind the options.
* The API reference of ``pipeline.api`` and of each of its theme modules
  (``pipeline.api.planning`` ...) must show every name of the module's ``__all__``: a name
  the rendered page lacks is a warning, which ``mkdocs build --strict`` turns into a failed
  build.

``tests/test_docs.py`` imports this module to check the same things without mkdocs.
"""

from __future__ import annotations

import argparse
import logging
import re

CLI_MARKER = "<!-- symfuse-cli-reference -->"
API_PAGE = "reference/api.md"
#: The theme modules of ``pipeline.api``, each rendered on ``reference/api-<theme>.md``.
API_THEMES = ("planning", "io", "sim", "perception", "estimation", "symmetry")
#: Page -> the module whose ``__all__`` it must show.
API_PAGES = {
    API_PAGE: "pipeline.api",
    **{f"reference/api-{theme}.md": f"pipeline.api.{theme}" for theme in API_THEMES},
}

log = logging.getLogger("mkdocs.hooks.symfuse_docs")


def cli_parser() -> argparse.ArgumentParser:
    """The ``symfuse`` parser: the one place the docs reach into the command line."""
    from pipeline.cli import build_parser

    return build_parser()


def verbs(
    parser: argparse.ArgumentParser, prefix: str = ""
) -> list[tuple[str, argparse.ArgumentParser]]:
    """Every verb of ``parser`` as ``(name, parser)``, nested verbs as ``"a b"``, in the
    order the parser declares them."""
    found: list[tuple[str, argparse.ArgumentParser]] = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                full = f"{prefix}{name}"
                found.append((full, sub))
                found.extend(verbs(sub, prefix=f"{full} "))
    return found


def documented_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The arguments a user types: every action but ``--help`` and the verb choice."""
    return [
        action
        for action in parser._actions
        if not isinstance(action, argparse._HelpAction | argparse._SubParsersAction)
    ]


def help_text(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The action's help as ``--help`` shows it (``%(default)s`` and the like expanded)."""
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return parser._get_formatter()._expand_help(action)


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _argument(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    names = ", ".join(f"`{name}`" for name in action.option_strings)
    if action.nargs == 0:
        return names
    if action.metavar is not None:
        value = action.metavar
    elif action.choices is not None:
        value = "{" + ",".join(str(choice) for choice in action.choices) + "}"
    else:
        value = action.dest.upper()
    value = " ".join(value) if isinstance(value, tuple) else value
    return f"{names} `{value}`"


def render_verb(name: str, parser: argparse.ArgumentParser) -> str:
    """One verb's section: heading, usage, description, the table of its arguments."""
    parser.format_help()  # a description computed when help is shown is filled in here
    usage = " ".join(parser.format_usage().removeprefix("usage: ").split())
    lines = [f"## symfuse {name}", "", "```text", usage, "```", ""]
    if parser.description:
        lines += [" ".join(parser.description.split()), ""]
    lines += ["| argument | what |", "|---|---|"]
    for action in documented_actions(parser):
        text = help_text(parser, action)
        choices = action.choices if action.choices is not None and action.metavar else None
        if choices is not None and not isinstance(choices, dict):
            text += f" (one of: {', '.join(str(choice) for choice in choices)})"
        lines.append(f"| {_argument(action)} | {_cell(text)} |")
    return "\n".join(lines) + "\n"


def render_cli_reference(parser: argparse.ArgumentParser) -> str:
    """The command line reference in Markdown: the global options, then every verb."""
    lines = ["## symfuse", "", "| argument | what |", "|---|---|"]
    for action in documented_actions(parser):
        lines.append(f"| {_argument(action)} | {_cell(help_text(parser, action))} |")
    sections = ["\n".join(lines) + "\n"]
    sections += [render_verb(name, sub) for name, sub in verbs(parser)]
    return "\n".join(sections)


def api_names(module: str = "pipeline.api") -> list[str]:
    """``module.__all__`` (``pipeline.api`` or one of its theme modules)."""
    from importlib import import_module

    return list(import_module(module).__all__)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, render_cli_reference(cli_parser()))
    return markdown


def on_page_content(html: str, page, config, files) -> str:
    module = API_PAGES.get(page.file.src_uri)
    if module is not None:
        prefix = re.escape(module + ".")
        shown = set(re.findall(f'id="{prefix}([A-Za-z_][A-Za-z0-9_]*)"', html))
        for name in api_names(module):
            if name not in shown:
                log.warning(
                    f"{page.file.src_uri}: {module}.{name} is in __all__ but not on the page"
                )
    return html
