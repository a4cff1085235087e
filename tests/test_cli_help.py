"""Every command's --help shows examples and defaults, and every example parses with the real parser."""

import contextlib
import io
import shlex

import pytest

from livesweep import cli

VERBS = sorted(cli.EXAMPLES)


def test_every_verb_has_examples():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "verb")
    assert set(sub.choices) == set(cli.EXAMPLES)


@pytest.mark.parametrize("verb", VERBS)
def test_help_shows_examples_and_defaults_and_the_examples_parse(verb):
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        cli.main([verb, "--help"])
    text = out.getvalue()
    assert "examples:" in text
    parser = cli.build_parser()
    for line in cli.EXAMPLES[verb]:
        assert line in text
        args = shlex.split(line)
        assert args[:2] == ["livesweep", verb]
        ns = parser.parse_args(args[1:])                   # argparse exits on an unknown flag or bad value
        assert ns.verb == verb
    sub = next(a for a in parser._actions if a.dest == "verb").choices[verb]
    for action in sub._actions:
        if (action.option_strings and isinstance(action.default, (int, float, str)) and not isinstance(action.default, bool)
                and action.default != "==SUPPRESS=="):
            assert f"default: {action.default}" in " ".join(text.split()) or "default" in (action.help or "").lower(), \
                action.option_strings
