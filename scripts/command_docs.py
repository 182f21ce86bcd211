#!/usr/bin/env python3
"""Fill the generated blocks of docs/commands/<command>.md from the program itself.

Each page holds up to two blocks, delimited by marker lines:
  <!-- BEGIN GENERATED flags: ... -->   ...   <!-- END GENERATED flags -->
  <!-- BEGIN GENERATED config: ... -->  ...   <!-- END GENERATED config -->
The flags block is `evio <command> --help`; the config block is a table of every key of
`evio <command> --print-config` (the tables the code reads and validates the config with) with its
default and its unit and range. So a key is documented exactly when the program has it.

  scripts/command_docs.py --evio build/apps/evio docs/commands            # rewrite the blocks
  scripts/command_docs.py --evio build/apps/evio --check docs/commands    # exit 1 when a page is stale
"""
import argparse
import difflib
import pathlib
import re
import subprocess
import sys

BLOCK = re.compile(r"(<!-- BEGIN GENERATED (flags|config):[^\n]*-->\n)(.*?)(<!-- END GENERATED \2 -->)", re.S)
KEY_LINE = re.compile(r"^( *)([A-Za-z0-9_.-]+):(?: (.*?))?(?:\s+# (.*))?$")


def run(evio, command, flag):
    out = subprocess.run([evio, command, flag], check=True, capture_output=True, text=True).stdout
    return out


def flags_block(evio, command):
    return "```text\n" + run(evio, command, "--help").rstrip("\n") + "\n```\n"


def config_keys(text):
    """(dotted key, default, unit and range) for every leaf of a --print-config listing."""
    rows, stack = [], []
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        m = KEY_LINE.match(line)
        if not m:
            raise SystemExit(f"command_docs.py: cannot read the --print-config line {line!r}")
        depth = len(m.group(1)) // 2
        del stack[depth:]
        value, comment = (m.group(3) or "").strip(), (m.group(4) or "").strip()
        if value == "" and comment == "":
            stack.append(m.group(2))
            continue
        rows.append((".".join(stack + [m.group(2)]), value, comment))
    return rows


def cell(s):
    return s.replace("|", "\\|") if s else " "


def config_block(evio, command):
    rows = config_keys(run(evio, command, "--print-config"))
    lines = ["| key | default | unit, range |", "|---|---|---|"]
    lines += [f"| `{k}` | `{cell(v)}` | {cell(c)} |" for k, v, c in rows]
    return "\n".join(lines) + "\n"


def regenerate(page, evio):
    command = page.stem
    text = page.read_text()

    def fill(m):
        body = flags_block(evio, command) if m.group(2) == "flags" else config_block(evio, command)
        return m.group(1) + body + m.group(4)

    return text, BLOCK.sub(fill, text)


def documented_keys(text):
    m = re.search(r"<!-- BEGIN GENERATED config:[^\n]*-->\n(.*?)<!-- END GENERATED config -->", text, re.S)
    return set(re.findall(r"^\| `([^`]+)` \|", m.group(1), re.M)) if m else set()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evio", required=True, help="the evio program (build/apps/evio)")
    ap.add_argument("--check", action="store_true", help="do not write; exit 1 when a page differs from the program")
    ap.add_argument("folder", type=pathlib.Path, help="docs/commands")
    a = ap.parse_args()
    pages = sorted(a.folder.glob("*.md"))
    if not pages:
        sys.exit(f"command_docs.py: no pages in {a.folder}")
    stale = 0
    for page in pages:
        old, new = regenerate(page, a.evio)
        if "BEGIN GENERATED flags" not in old:
            print(f"{page}: no generated flags block")
            stale += 1
            continue
        if old == new:
            continue
        if not a.check:
            page.write_text(new)
            print(f"{page}: updated")
            continue
        stale += 1
        have, want = documented_keys(old), documented_keys(new)
        for k in sorted(want - have):
            print(f"{page}: config key `{k}` is not documented")
        for k in sorted(have - want):
            print(f"{page}: documents `{k}`, which `evio {page.stem} --print-config` does not have")
        diff = difflib.unified_diff(old.splitlines(), new.splitlines(), str(page), "generated", lineterm="", n=1)
        print("\n".join(list(diff)[:40]))
    if stale:
        print(f"{stale} page(s) out of date: run scripts/command_docs.py --evio build/apps/evio docs/commands")
        sys.exit(1)


if __name__ == "__main__":
    main()
