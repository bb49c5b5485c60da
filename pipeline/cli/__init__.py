"""The ``symfuse`` command line.

Every deliberate failure (:class:`~pipeline.errors.SymfuseError`) is printed as one line,
``symfuse: error: ...``, with its exit code (:mod:`pipeline.errors`: 2 bad input or config,
3 a failed estimate, 4 a plugin raised, 130 interrupted); ``--debug`` shows the traceback
instead. Every verb that writes follows the output-folder policy of :mod:`pipeline.io.outdir`.

This module holds the options the verbs share, ``plugins`` and ``config``, the parser and
:func:`main`; every other verb lives in its own module of this package with an
``add_parser`` and a ``run``.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

from pipeline import __version__
from pipeline.entry import interrupt_received, report_interrupt
from pipeline.errors import EXIT_BAD_INPUT, EXIT_OK, ConfigError, SymfuseError
from pipeline.reports.tables import WrappedFormatter, format_table
from pipeline.stages import STAGES


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        action="append",
        type=Path,
        default=[],
        metavar="FILE",
        help="TOML config merged over the defaults (repeatable; later files win)",
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one config value, e.g. --set estimator.use=icp (repeatable)",
    )


def _add_output_options(parser: argparse.ArgumentParser, default: str | None) -> None:
    """``--out`` (required when ``default`` is None) and ``--overwrite``."""
    parser.add_argument(
        "--out",
        type=Path,
        required=default is None,
        metavar="DIR",
        help="output folder" + (f" (default: a fresh {default})" if default else ""),
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing, non-empty --out folder (whole, when the run ends)",
    )


def _add_units_option(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--units",
        choices=["m", "mm"],
        help=f"length unit of {what} (default: metres; data that looks like millimetres "
        "is refused)",
    )


def add_wide_option(parser: argparse.ArgumentParser) -> None:
    """``--wide``: print every column of the result tables, not only those that fit a
    terminal (all are in ``result.json`` either way)."""
    parser.add_argument(
        "--wide",
        action="store_true",
        help="print every column of the tables (default: those that fit 100 columns)",
    )


def counting_number(least: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer of at least ``least`` (a seed >= 0, a count >= 1)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected an integer >= {least}, got {value}")
        return value

    return parse


def _load(
    args: argparse.Namespace,
    reads: Sequence[str] | None = None,
    registry=None,
    defaults: Mapping[str, Any] | None = None,
):
    """The registry and the config of ``--config``, ``--set`` and the verb's own options
    that stand for config keys (:mod:`pipeline.cli.options`, applied last).

    Args:
        reads: the config sections the verb reads (None: all); see :func:`check_overrides`.
        registry: the installed plugins, when the caller has loaded them already.
        defaults: the verb's own defaults (a nested dict), merged over the shipped ones
            before ``--config``.
    """
    from pipeline.cli.options import option_overrides
    from pipeline.config import load_config
    from pipeline.registry import load_registry

    registry = registry or load_registry()
    options = option_overrides(args)
    config = load_config(
        registry,
        args.config,
        args.overrides,
        options=options,
        command_defaults=(f"symfuse {args.verb}", defaults) if defaults else None,
    )
    check_overrides(args.verb, args.overrides, [text for text, _ in options], reads)
    if args.verb != "config":  # `symfuse config` writes a config to use later: any key goes
        check_selected(args.overrides, config, registry)
    if args.config and reads is not None:
        note_unread_sections(args.verb, args.config, config, reads)
    return registry, config


def note_unread_sections(verb: str, files: Sequence[Path], config, reads: Sequence[str]) -> None:
    """Say which sections of the ``--config`` files ``verb`` does not read, where they
    differ from the defaults. A note, not an error (a ``--set`` there is one): a config
    written by another command, a trial's ``config.toml`` say, is a whole resolved config
    and is meant to be reusable."""
    changed = config.changed_sections([str(path) for path in files])
    unread = sorted(set(changed) - set(reads))
    if unread:
        print(
            f"note: symfuse {verb} does not read [{'], ['.join(unread)}], which "
            f"{', '.join(str(f) for f in files)} changes: those settings have no effect"
        )


def check_overrides(
    verb: str, overrides: Sequence[str], options: Sequence[str], reads: Sequence[str] | None
) -> None:
    """Refuse a ``--set`` that would be ignored without a word: one in a section ``verb``
    does not read, or one whose key the verb's own options also set (they win).

    Args:
        overrides: the user's ``--set`` texts (``section.key=value``), already valid.
        options: the overrides the verb's options stand for.
        reads: the sections ``verb`` reads (None: all).

    Raises:
        ConfigError: naming the ``--set`` and why it would be ignored.
    """
    taken = {text.partition("=")[0].strip() for text in options}
    for text in overrides:
        key = text.partition("=")[0].strip()
        section = key.split(".")[0]
        if reads is not None and section not in reads:
            raise ConfigError(
                f"--set {text}: symfuse {verb} does not read [{section}] (it reads "
                f"[{'], ['.join(reads)}])"
            )
        if key in taken:
            raise ConfigError(
                f"--set {text}: symfuse {verb} sets {key} from its arguments; drop this --set"
            )


def check_selected(overrides: Sequence[str], config, registry) -> None:
    """Refuse a ``--set STAGE.NAME.KEY=VALUE`` for an implementation the run does not use:
    ``STAGE.use`` names another, so the value would be ignored without a word. Two stages
    read more than the one they use: every hand's planner plans with ``trial.gripper =
    "auto"``, and an estimator without a taxel model of its own takes another's for the
    next-grasp score.

    Raises:
        ConfigError: naming the ``--set`` and the implementation in use.
    """
    from pipeline.stages import Estimator

    for text in overrides:
        parts = text.partition("=")[0].strip().split(".")
        if len(parts) != 3 or parts[0] not in STAGES or parts[1] == config.choices[parts[0]]:
            continue
        stage, name = parts[0], parts[1]
        used = config.choices[stage]
        if stage == "planner" or (
            stage == "estimator"
            and registry.get(stage, used).cls.measurement_model is Estimator.measurement_model
        ):
            continue
        raise ConfigError(
            f"--set {text}: {stage}.use is '{used}', so {stage}.{name}'s parameters have no "
            f"effect; add --set {stage}.use={name}, or drop this --set"
        )


# --- symfuse plugins -------------------------------------------------------------------


def _cmd_plugins(args: argparse.Namespace) -> int:
    from pipeline.config import load_config
    from pipeline.params import describe
    from pipeline.registry import load_registry

    registry = load_registry()
    rows = []
    for stage in STAGES:
        names = registry.names(stage)
        if not names:
            rows.append([stage, "(none installed)", "", "", ""])
        for name in names:
            reg = registry.get(stage, name)
            rows.append(
                [stage, name, reg.origin.distribution, reg.origin.version, reg.cls.description()]
            )
    print(format_table(["stage", "name", "distribution", "version", "description"], rows))
    if args.params:
        # The effective defaults: the shipped config's values where it sets any.
        shipped = load_config(registry).params
        for registration in registry.registrations():
            values = shipped[registration.stage].get(registration.name)
            infos = describe(registration.cls.Params, values)
            print(f"\n[{registration.stage}.{registration.name}]")
            if not infos:
                print("  (no parameters)")
            for info in infos:
                print(f"  {info.name} = {info.default!r}  ({info.type_name}) {info.doc}")
    return EXIT_OK


# --- symfuse config --------------------------------------------------------------------


def _cmd_config(args: argparse.Namespace) -> int:
    registry, config = _load(args)
    config.check_stages(registry)
    print(config.to_toml(), end="")
    return 0


# --- the parser ------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose description can be computed only when help is shown
    (``describe=``), so building the CLI never imports what only the help text needs."""

    def __init__(self, *args, describe: Callable[[], str] | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._describe = describe

    def format_help(self) -> str:
        if self._describe is not None:
            self.description = self._describe()
        return super().format_help()

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> Any:
        # An empty value (`--init ""`, `--plane=`) reads as "not given" wherever the verb
        # tests the option's truth, so the user's choice would be dropped without a word.
        if action.option_strings and "" in arg_strings:
            self.error(f"argument {'/'.join(action.option_strings)}: the value is empty")
        return super()._get_values(action, arg_strings)

    def error(self, message: str) -> NoReturn:
        """A command-line mistake as every other error: one line, exit code 2 (argparse
        would print the usage first and prefix the verb's name differently)."""
        verb = self.prog.removeprefix("symfuse").strip()
        where = f"{verb}: " if verb else ""
        hint = f"symfuse {verb} --help" if verb else "symfuse --help"
        self.exit(EXIT_BAD_INPUT, f"symfuse: error: {where}{message} (see {hint})\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="symfuse",
        description="Visuo-tactile reconstruction of symmetric objects: mirror-complete a "
        "single depth view, grasp, and fuse taxel contacts with the cloud (IEKF).",
    )
    parser.add_argument("--version", action="version", version=f"symfuse {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)

    plugins = verbs.add_parser(
        "plugins",
        help="list the installed stage implementations",
        description="List every stage with its installed implementations: name, "
        "distribution, version and description.",
    )
    plugins.add_argument("--params", action="store_true", help="also list every parameter")
    plugins.set_defaults(run=_cmd_plugins)

    config = verbs.add_parser(
        "config",
        help="print the resolved configuration",
        description="Print the configuration that a run with these options would use, "
        "every parameter included, as TOML.",
    )
    _add_config_options(config)
    config.set_defaults(run=_cmd_config)

    from pipeline.cli import complete, fuse, objects, sweep, symmetry, trial, view

    for verb in (fuse, trial, sweep, complete, objects, symmetry, view):
        verb.add_parser(verbs).set_defaults(run=verb.run)
    return parser


#: Options whose value may start with a minus sign (``--plane -1,0,0.2``).
SIGNED_VALUE_OPTIONS = ("--plane", "--symmetry")


def _join_signed_values(argv: Sequence[str]) -> list[str]:
    """``--plane -1,0,0.2`` as ``--plane=-1,0,0.2``: argparse takes a value that starts with
    ``-`` and is not a plain number for an option and reports "expected one argument"."""
    joined: list[str] = []
    for argument in argv:
        if joined and joined[-1] in SIGNED_VALUE_OPTIONS and argument.startswith("-"):
            joined[-1] = f"{joined[-1]}={argument}"
        else:
            joined.append(argument)
    return joined


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; its exit code. Ctrl-C gives 130 whatever error it caused, or none
    (:mod:`pipeline.entry`, the console script, notes it from the first instant)."""
    if logging.lastResort is not None:
        # The handler that prints the warnings of a command line without logging set up.
        logging.lastResort.setFormatter(WrappedFormatter())
    parser = build_parser()
    args, unknown = parser.parse_known_args(
        _join_signed_values(sys.argv[1:] if argv is None else argv)
    )
    if unknown:
        # Named by the verb's parser, so the message points at the verb's own --help.
        verb_parser(parser, args.verb).error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        code = args.run(args)
    except SymfuseError as exc:
        if args.debug:
            raise
        if interrupt_received():
            return report_interrupt()
        print(f"symfuse: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return report_interrupt()
    except BrokenPipeError:
        # The reader of stdout left (`symfuse objects | head`): nothing more to say, and
        # Python must not fail again flushing stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:
        if not (interrupted(exc) or interrupt_received()):
            raise
        return report_interrupt()
    return report_interrupt() if interrupt_received() else code


def verb_parser(parser: argparse.ArgumentParser, verb: str) -> argparse.ArgumentParser:
    """The sub-parser of ``verb`` in :func:`build_parser`'s ``parser``."""
    verbs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return verbs.choices[verb]


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by Ctrl-C: a compiled extension interrupted while it
    initialises (open3d's pybind11 module) raises ImportError from the KeyboardInterrupt."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False
