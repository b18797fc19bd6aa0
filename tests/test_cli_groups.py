"""The CLI builds only the parser of the command it runs (start-up time)."""

from __future__ import annotations

import argparse
import subprocess
import sys

from spectrageo.cli import main as cli_main


def test_command_groups_name_what_each_module_registers():
    for group, names in cli_main.COMMAND_GROUPS.items():
        p = argparse.ArgumentParser()
        sub = p.add_subparsers()
        cli_main._group(group).register(sub)
        assert tuple(sub.choices) == names, group


def test_full_parser_has_every_command_in_help_order():
    p = cli_main.build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    expected = [n for names in cli_main.COMMAND_GROUPS.values() for n in names]
    assert list(sub.choices) == expected
    # an unknown first word builds the whole parser, so argparse lists every choice
    assert cli_main.build_parser("registr")._actions[-1].choices.keys() == sub.choices.keys()


def test_register_command_does_not_import_the_codecs():
    code = (
        "import sys; from spectrageo.cli.main import build_parser; "
        "p = build_parser('register'); p.parse_args(['register', 'a.ply', 'b.ply', '--out', 'T.json']); "
        "print(sorted(m for m in ('spectrageo.compress', 'spectrageo.denoise', 'spectrageo.learn') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_unknown_command_is_refused_with_the_choices(capsys):
    assert _exit_code(["registr"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def _exit_code(argv):
    try:
        return cli_main.main(argv)
    except SystemExit as exc:
        return exc.code


def test_evaluate_compress_takes_a_split(tmp_path, capsys):
    # an empty data folder: the split is accepted, then no model of it is found
    assert _exit_code(["evaluate", "compress", "--data", str(tmp_path), "--split", "tuning"]) == 2
    assert "no compress benchmark data found" in capsys.readouterr().err
    argv = ["evaluate", "compress", "--data", str(tmp_path), "--split", "both", "--levels", "0.1"]
    assert _exit_code(argv) == 2
    assert "`--levels` applies to `evaluate denoise --split` only" in capsys.readouterr().err
