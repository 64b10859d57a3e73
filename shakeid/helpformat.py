"""How `shakeid ... --help` shows each option: its help text, its unit, and its default; and how a usage
error is told (one line).

The default is appended as "(default: X)" from the parser itself, so the help cannot drift from the
code. Options whose default is computed (None: "the config's port, else 5020") say it in words, with
"default" in the text, and get nothing appended; flags (store_true) have no default to show.
"""
from __future__ import annotations

import argparse
import functools


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text.lower() or not action.option_strings:
            return text  # said in words already; positionals have no default to show
        if action.default is None or action.default is argparse.SUPPRESS or isinstance(action.default, bool):
            return text
        if action.default in ("", []):
            return text + " (default: none)"
        return text + " (default: %(default)s)"


class OneLineErrors(argparse.ArgumentParser):
    """A usage error is one line, as every other shakeid error ("shakeid: error: argument --mass-kg: must be
    > 0, got 0"), pointing at --help rather than printing the whole usage (identify's is 16 lines).
    Options are taken whole, never abbreviated: argparse's default read `shakeid explain ... --output V2
    --out DIR` as a second --output, the channel "DIR", and failed naming a missing variable DIR."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_args(self, args=None, namespace=None):
        """argparse's, but an unrecognized option is told by the subcommand it was given to (`shakeid
        explain --help` lists the options), not by the top-level parser."""
        known, extras = self.parse_known_args(args, namespace)
        if extras:
            self._chosen(known).error(f"unrecognized arguments: {' '.join(extras)}")
        return known

    def _chosen(self, known) -> argparse.ArgumentParser:
        """The innermost (sub)parser the command line chose."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                sub = action.choices.get(getattr(known, action.dest, None) or "")
                if sub is not None:
                    return sub._chosen(known) if isinstance(sub, OneLineErrors) else sub
        return self

    def error(self, message):
        self.exit(2, f"shakeid: error: {message} (`{self.prog} --help` lists the options)\n")


#: the parser class of every `shakeid` subcommand (add_subparsers(parser_class=...)): defaults shown
Parser = functools.partial(OneLineErrors, formatter_class=HelpFormatter)
