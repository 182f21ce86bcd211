#!/usr/bin/env python3
"""docs/commands/ against the program: every subcommand has a page, and every page's generated
blocks equal what the program prints (scripts/command_docs.py --check); the check itself fails on
a page with a config key removed and on one with a key the program does not have.
  check_command_docs.py EVIO SOURCE_DIR"""
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

evio, src = sys.argv[1], pathlib.Path(sys.argv[2])
script, pages = src / "scripts" / "command_docs.py", src / "docs" / "commands"


def check(folder):
    r = subprocess.run([sys.executable, str(script), "--evio", evio, "--check", str(folder)], capture_output=True, text=True)
    return r.returncode, r.stdout + r.stderr


help_text = subprocess.run([evio, "--help"], check=True, capture_output=True, text=True).stdout
commands = re.findall(r"^  ([a-z]+) ", help_text.split("Subcommands:")[1], re.M)
assert len(commands) >= 10, help_text
missing = [c for c in commands if not (pages / f"{c}.md").exists()]
assert not missing, f"no docs/commands page for: {missing}"

rc, out = check(pages)
assert rc == 0, out

with tempfile.TemporaryDirectory() as tmp:
    page = pathlib.Path(tmp) / "vio.md"
    shutil.copy(pages / "vio.md", page)
    text = page.read_text()
    removed = re.sub(r"^\| `window\.size` \|[^\n]*\n", "", text, count=1, flags=re.M)
    assert removed != text, "vio.md has no `window.size` row"
    page.write_text(removed)
    rc, out = check(tmp)
    assert rc == 1 and "config key `window.size` is not documented" in out, out
    page.write_text(text.replace("| `window.size` |", "| `window.no_such_key` | `1` | |\n| `window.size` |", 1))
    rc, out = check(tmp)
    assert rc == 1 and "documents `window.no_such_key`" in out, out
print(f"docs/commands: {len(commands)} commands documented, generated blocks current")
