#!/usr/bin/env python3
"""Checks that the Dockerfile's build stage has every file the build needs, without Docker.

No Docker daemon runs on the project's machines, so CI rebuilds the build context the way
`docker build .` would: the sources of each COPY line of the first stage (minus
.dockerignore) copied to a temporary directory. There it checks that

1. `cargo metadata --locked --offline` loads the workspace (every member and target is
   there and Cargo.lock matches), and
2. every file that an `include_str!`/`include_bytes!` in the compiled sources names is inside
   the context. Test modules (`tests.rs`, `tests/`, `benches/`) are not compiled by
   `cargo build --release` and are not scanned. A form of include this script cannot resolve
   is an error, so a new one is extended here rather than skipped.

Usage: python3 .ci/docker_context.py [Dockerfile]   (from the repository root)
"""

import fnmatch
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.getcwd()
# The build platform: the image builds for the machine's own (Linux) target, so crates of
# other platforms need not be in the offline cache.
HOST = next(
    l.split(": ", 1)[1]
    for l in subprocess.run(["rustc", "-vV"], capture_output=True, text=True, check=True).stdout.splitlines()
    if l.startswith("host: ")
)


def build_stage_copies(dockerfile):
    """(sources, destination) of each COPY line of the first stage, without --from."""
    copies, stage = [], 0
    with open(dockerfile) as f:
        lines = f.read().replace("\\\n", " ").splitlines()
    for line in lines:
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0].upper() == "FROM":
            stage += 1
            if stage > 1:
                break
        if words[0].upper() in ("COPY", "ADD"):
            args = [w for w in words[1:] if not w.startswith("--")]
            if any(w.startswith("--from") for w in words[1:]):
                continue
            copies.append((args[:-1], args[-1]))
    return copies


def ignored_patterns():
    path = os.path.join(ROOT, ".dockerignore")
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [l.strip().rstrip("/") for l in f if l.strip() and not l.startswith("#")]


def is_ignored(rel, patterns):
    return any(fnmatch.fnmatch(rel, p) or rel.startswith(p + "/") for p in patterns)


def make_context(copies, ctx, patterns):
    """Docker's rules: a directory's contents go into the destination; a file goes into it
    when it ends with / or there are several sources, else it is the destination."""
    for sources, dest in copies:
        into = dest.endswith("/") or dest in (".", "./") or len(sources) > 1
        for src in sources:
            full = os.path.join(ROOT, src)
            if not os.path.exists(full):
                sys.exit(f"COPY {src}: no such file in the repository")
            if os.path.isdir(full):
                for d, dirs, files in os.walk(full):
                    dirs[:] = [x for x in dirs if not is_ignored(os.path.relpath(os.path.join(d, x), ROOT), patterns)]
                    for name in files:
                        if is_ignored(os.path.relpath(os.path.join(d, name), ROOT), patterns):
                            continue
                        out = os.path.join(ctx, dest, os.path.relpath(os.path.join(d, name), full))
                        os.makedirs(os.path.dirname(out), exist_ok=True)
                        shutil.copy2(os.path.join(d, name), out)
            else:
                out = os.path.join(ctx, dest, os.path.basename(src)) if into else os.path.join(ctx, dest)
                os.makedirs(os.path.dirname(out), exist_ok=True)
                shutil.copy2(full, out)


INCLUDE = re.compile(r"include_(?:str|bytes)!\s*\((.*?)\)\s*[,;)\]]", re.S)
LITERAL = re.compile(r'"((?:[^"\\]|\\.)*)"')


def manifest_dir(path, ctx):
    d = os.path.dirname(path)
    while d.startswith(ctx):
        if os.path.exists(os.path.join(d, "Cargo.toml")):
            return d
        d = os.path.dirname(d)
    sys.exit(f"{path}: no Cargo.toml above it")


def include_targets(path, text, ctx):
    """The files the includes of one source file name (absolute paths)."""
    out = []
    for m in INCLUDE.finditer(text):
        arg = m.group(1).strip()
        line = text[: m.start()].count("\n") + 1
        where = f"{os.path.relpath(path, ctx)}:{line}"
        base = os.path.dirname(path)
        if arg.startswith("concat!"):
            inner = arg[len("concat!"):].strip()[1:]
            if 'env!("CARGO_MANIFEST_DIR")' in inner:
                base = manifest_dir(path, ctx)
                inner = inner.replace('env!("CARGO_MANIFEST_DIR")', "")
            parts = LITERAL.findall(inner)
            rest = LITERAL.sub("", inner).replace(",", "").strip()
            if rest.startswith("$") and re.fullmatch(r"\$\w+\)?", rest):
                # Inside a macro_rules!: the metavariable takes the first literal of each call.
                macro = None
                for mm in re.finditer(r"macro_rules!\s*(\w+)", text[: m.start()]):
                    macro = mm.group(1)
                if macro is None:
                    sys.exit(f"{where}: cannot resolve include_*!({arg})")
                calls = re.findall(macro + r'!\s*\(\s*"((?:[^"\\]|\\.)*)"', text)
                if not calls:
                    sys.exit(f"{where}: no calls of {macro}! to resolve include_*!({arg})")
                out += [(where, os.path.join(base, "".join(parts) + c)) for c in calls]
                continue
            if rest:
                sys.exit(f"{where}: cannot resolve include_*!({arg}); extend .ci/docker_context.py")
            out.append((where, os.path.join(base, "".join(parts))))
        elif LITERAL.fullmatch(arg):
            out.append((where, os.path.join(base, LITERAL.fullmatch(arg).group(1))))
        else:
            sys.exit(f"{where}: cannot resolve include_*!({arg}); extend .ci/docker_context.py")
    return out


def is_test_source(rel):
    parts = rel.split(os.sep)
    return parts[-1] == "tests.rs" or "tests" in parts[:-1] or "benches" in parts[:-1]


def main():
    dockerfile = sys.argv[1] if len(sys.argv) > 1 else "Dockerfile"
    copies = build_stage_copies(dockerfile)
    if not copies:
        sys.exit(f"{dockerfile}: no COPY line in the build stage")
    with tempfile.TemporaryDirectory() as ctx:
        make_context(copies, ctx, ignored_patterns())
        r = subprocess.run(
            ["cargo", "metadata", "--locked", "--offline", "--format-version", "1", "--filter-platform", HOST],
            cwd=ctx, capture_output=True, text=True,
        )
        if r.returncode != 0:
            sys.exit(f"cargo metadata fails in the Docker build context:\n{r.stderr}")
        meta = json.loads(r.stdout)
        members = [p for p in meta["packages"] if p["id"] in meta["workspace_members"]]
        checked, missing = 0, []
        for d, _, files in os.walk(ctx):
            for name in files:
                path = os.path.join(d, name)
                rel = os.path.relpath(path, ctx)
                if not name.endswith(".rs") or is_test_source(rel):
                    continue
                with open(path, encoding="utf-8") as f:
                    text = f.read()
                for where, target in include_targets(path, text, ctx):
                    checked += 1
                    target = os.path.normpath(target)
                    if not target.startswith(ctx + os.sep) or not os.path.isfile(target):
                        missing.append(f"{where}: {os.path.relpath(target, ctx)}")
        if missing:
            sys.exit("files included by the build but not in the Docker build context:\n  " + "\n  ".join(missing))
        names = ", ".join(p["name"] for p in members)
        print(f"Docker build context: {len(copies)} COPY lines; cargo metadata loads {names}; "
              f"{checked} include_str!/include_bytes! targets all inside")


if __name__ == "__main__":
    main()
