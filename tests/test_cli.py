"""The command line: every subcommand explains itself; errors exit 2 without a traceback."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from wrinklepipe.cli import COMMAND_ORDER, build_parser, main


def _subcommands() -> dict:
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return dict(action.choices)


def test_every_command_has_help(capsys):
    for name, sub in _subcommands().items():
        text = sub.format_help()
        assert len(sub.description or "") > 20, name
        assert "usage: wrinklepipe " + name in text


def test_help_exits_zero(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    assert "bench" in capsys.readouterr().out


def test_one_command_loads_its_own_module_only(capsys):
    """``wrinklepipe convert`` builds convert's parser alone: in a fresh interpreter no other
    command's module (nor capture's solvers, nor the batch engines) is imported; ``--help`` and
    a mistyped name still see every command."""
    probe = (
        "import sys\nfrom wrinklepipe.cli import main\n"
        "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in sys.modules if m.startswith('wrinklepipe.commands.')"
        " and not m.startswith('wrinklepipe.commands._')))"
    )
    one = subprocess.run(
        [sys.executable, "-c", probe, "convert", "--help"], capture_output=True, text=True
    )
    assert one.returncode == 0, one.stderr
    assert one.stdout.splitlines()[-1] == "['wrinklepipe.commands.convert']"
    assert "usage: wrinklepipe convert" in one.stdout
    with pytest.raises(SystemExit) as info:
        main(["convrt"])
    assert info.value.code == 2
    text = capsys.readouterr().err
    assert "invalid choice: 'convrt'" in text
    assert all(f"'{name}'" in text for name in COMMAND_ORDER)


def test_no_command_prints_help_and_exits_2(capsys):
    assert main([]) == 2


def test_bench_lists_and_runs_quick(capsys):
    assert main(["bench", "--list"]) == 0
    assert "model-metahuman" in capsys.readouterr().out
    assert main(["bench", "model-metahuman", "--quick", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    rows = payload["results"][0]["rows"]
    assert rows[0]["step"] == "einsum over mask stack" and rows[0]["ratio"] == 1.0
    assert all(r["median_s"] > 0 for r in rows)


def test_bench_unknown_name_exits_2(capsys):
    assert main(["bench", "nope"]) == 2
    assert "unknown benchmark" in capsys.readouterr().err


def test_every_command_of_the_brief_is_there():
    assert list(_subcommands()) == list(COMMAND_ORDER)


def test_bench_limits_ratio_and_seconds():
    from wrinklepipe.bench import BenchResult, BenchRow

    r = BenchResult("x", "d", baseline="base")
    r.rows = [BenchRow("base", 0.010), BenchRow("fast", 0.015), BenchRow("slow", 0.050)]
    r.limits = {"fast": 2.0, "slow": 4.0}
    r.limits_s = {"fast": 0.001}
    r.finish()
    assert [row.ratio for row in r.rows] == [1.0, 1.5, 5.0]
    assert r.failures() == ["x: slow ratio 5.00 > 4.0", "x: fast 0.015 s > 0.001 s"]
    assert r.limit_text("fast") == "<= 2x, <= 1 ms" and r.limit_text("base") == ""
