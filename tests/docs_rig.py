"""Run the command blocks of README.md and docs/*.md against the virtual drives.

What runs (docs/testing.md, "Docs that hold"):
- shell blocks, fenced ``sh``, ``bash``, ``console`` or untagged: every line, in order;
- Python blocks: exec'd (top-level ``await`` allowed), in a scratch directory.
A ``text`` fence is not a command (diagrams, output, wire layouts).

Markers, an HTML comment on the line before the fence (invisible when rendered):
- ``<!-- docs-test: skip REASON -->``: not run, reported as a skip with REASON (a block that
  names hardware says which: a serial port, a CAN adapter, a DYN5 at a plant address);
- ``<!-- docs-test: first COMMAND -->`` (may repeat): a server the block needs, started in
  the background first, e.g. the virtual drive the README's Python example talks to.

How:
- every literal port of a block (``127.0.0.1:4001``, ``--tcp-port 44818``, ``--port 8081``)
  becomes a free port; commands with an implicit default port get it written out;
- servers (``servobus sim <protocol>`` with a listener, ``gui``, ``serve``) are real
  processes, started in the background, awaited until their ports answer, and stopped by
  SIGINT at the end of the block (they must still run then, or have ended with 0);
- streams that run until Ctrl-C (``sniff``, ``io``) run for ``--duration`` STREAM_S;
- other ``servobus`` lines run in-process (``servobus.cli.main.main``) and must exit 0;
  ``echo 'TEXT' | servobus ...`` runs in-process with TEXT on stdin; other lines with shell
  syntax (pipes, ``&``, ``$``) run under bash;
- drive URLs of servers in Python blocks (``dyn232+socket://127.0.0.1:4001``) stay as
  written: the block's ``first`` marker starts that server;
- ``cell.toml`` and ``m.toml`` in the scratch directory are docs/machine.md's example
  machine file with its links on in-process virtual drives (``sim://...``).
"""

from __future__ import annotations

import ast
import asyncio
import contextlib
import inspect
import io
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from rig import free_port, wait_until

ROOT = Path(__file__).resolve().parent.parent
SHELL_FENCES = {"sh", "bash", "console", ""}
PYTHON_FENCES = {"python", "py"}
MARKER = re.compile(r"^<!--\s*docs-test:\s*(skip|first)\s+(.*?)\s*-->\s*$")
FENCE = re.compile(r"^\s*```(\w*)\s*$")  # indented too (a block inside a list item)
PORT_IN_TEXT = re.compile(
    r"(?:127\.0\.0\.1:|--tcp-port |--udp-port |--port |--gui-port )(\d{4,5})\b")
STREAMS = {"sniff", "io"}  # commands that run until Ctrl-C: run for STREAM_S here
STREAM_S = "0.5"
SHELL_SYNTAX = re.compile(r"[|&$<>]")
ECHO_PIPE = re.compile(r"^echo '([^']*)' \| (servobus [^|&$<>]*)$")
BIN = Path(sys.executable).parent


@dataclass
class Block:
    """One fenced command block of a Markdown file."""

    path: str  # relative to the repository root
    line: int  # the fence's line, 1-based
    lang: str
    text: str
    skip: str | None = None
    first: list[str] = field(default_factory=list)

    @property
    def kind(self) -> str:
        return "python" if self.lang in PYTHON_FENCES else "shell"

    @property
    def id(self) -> str:
        return f"{self.path}:{self.line}"


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def blocks_of(path: Path) -> list[Block]:
    """The shell and Python blocks of one Markdown file, with their markers."""
    lines = path.read_text(encoding="utf-8").split("\n")
    found: list[Block] = []
    index = 0
    while index < len(lines):
        fence = FENCE.match(lines[index])
        if not fence:
            index += 1
            continue
        end = index + 1
        while not lines[end].lstrip().startswith("```"):
            end += 1
        lang = fence.group(1).lower()
        if lang in SHELL_FENCES | PYTHON_FENCES:
            block = Block(str(path.relative_to(ROOT)), index + 1, lang,
                          textwrap.dedent("\n".join(lines[index + 1:end])))
            above = index - 1
            while above >= 0 and (marker := MARKER.match(lines[above].strip())):
                if marker.group(1) == "skip":
                    block.skip = marker.group(2)
                else:
                    block.first.insert(0, marker.group(2))
                above -= 1
            found.append(block)
        index = end + 1
    return found


def needs_processes(block: Block) -> bool:
    """Blocks that start real processes (servers, streams, shell syntax): ``slow``."""
    if block.first:
        return True
    if block.kind == "python":
        return False
    for command in commands_of(block.text):
        if SHELL_SYNTAX.search(command.split(" #", 1)[0]) and not ECHO_PIPE.match(command):
            return True
        with contextlib.suppress(ValueError):
            if is_background(words_of(command)):
                return True
    return False


def params(blocks: list[Block]) -> list[object]:
    """pytest parameters: one per block, ``slow`` where it starts processes."""
    import pytest

    return [pytest.param(block, id=block.id,
                         marks=[pytest.mark.slow] if needs_processes(block) else [])
            for block in blocks]


def all_blocks(names: tuple[str, ...] | None = None) -> list[Block]:
    files = doc_files()
    if names is not None:
        files = [f for f in files if str(f.relative_to(ROOT)) in names]
    return [block for path in files for block in blocks_of(path)]


def with_free_ports(text: str) -> str:
    """Every literal port of the block replaced by a free one (the same one each time)."""
    ports = {int(p) for p in PORT_IN_TEXT.findall(text)}
    mapping = {port: free_port() for port in sorted(ports)}
    for old, new in mapping.items():
        text = re.sub(rf"(?<![\d.]){old}(?!\d)", str(new), text)
    enip = re.search(r"--tcp-port (\d+)", text)
    if enip:  # enip:// and discover use 44818 unless told: tell them the block's port
        text = re.sub(r"enip://127\.0\.0\.1(?![:\d])", f"enip://127.0.0.1:{enip[1]}", text)
        text = re.sub(r"\bdiscover\b", f"discover --port {enip[1]}", text)
    return text


def commands_of(text: str) -> list[str]:
    """The block's commands: one per line (``\\`` continues one), split at `` ; ``."""
    joined = re.sub(r"\\\n", " ", text)
    commands: list[str] = []
    for line in joined.split("\n"):
        line = line.strip()
        if line.startswith("$ "):
            line = line[2:]
        if not line or line.startswith("#"):
            continue
        code, _, comment = line.partition(" #")
        parts = [part.strip() for part in code.split(" ; ") if part.strip()]
        if comment and parts:
            parts[-1] += f" #{comment}"
        commands.extend(parts)
    return commands


def words_of(command: str) -> list[str]:
    """The words of a command, its trailing ``  # comment`` left out (``02e#ff63`` stays)."""
    return shlex.split(re.split(r"\s#", command, maxsplit=1)[0])


def is_background(words: list[str]) -> bool:
    """Servers and streams: they run until Ctrl-C."""
    if not words or words[0] != "servobus":
        return False
    args = [w for w in words[1:] if not w.startswith("-")]
    rest = words[1:]
    if "sim" in rest:
        after = rest[rest.index("sim") + 1:]
        return bool(after) and after[0] != "control"
    return bool(args) and args[0] in {"gui", "serve"}


def stream_words(words: list[str]) -> list[str]:
    """A stream (``sniff``, ``io``) given a ``--duration`` unless it has one (or a count)."""
    if any(w in STREAMS for w in words) and not {"--duration", "--count"} & set(words):
        return [*words, "--duration", STREAM_S]
    return words


def server_words(words: list[str]) -> list[str]:
    """Defaults that would collide or open a browser, made explicit."""
    words = list(words)
    if "gui" in words and "--port" not in words:
        words += ["--port", str(free_port())]
    if "gui" in words and "--no-browser" not in words:
        words.append("--no-browser")
    if "serve" in words and "--opcua" not in words:
        words += ["--opcua", f"opc.tcp://127.0.0.1:{free_port()}"]
    return words


def ports_of(words: list[str]) -> list[int]:
    """The TCP ports a server line listens on."""
    ports = [int(m) for m in re.findall(r"127\.0\.0\.1:(\d{4,5})", " ".join(words))]
    ports += [int(words[i + 1]) for i, w in enumerate(words[:-1])
              if w in {"--tcp-port", "--port"} and words[i + 1].isdigit()]
    ports += [int(m) for m in re.findall(r"opc\.tcp://127\.0\.0\.1:(\d+)", " ".join(words))]
    return ports


def answers(port: int) -> bool:
    with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.5):
        return True
    return False


@dataclass
class Outcome:
    code: int
    stdout: str
    stderr: str


def run_in_process(words: list[str], env: dict[str, str]) -> Outcome:
    """``servobus ...`` through the CLI's main(), its output captured."""
    from servobus.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    saved = {key: os.environ.get(key) for key in env}
    os.environ.update(env)
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main(words[1:])
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return Outcome(code, out.getvalue(), err.getvalue())


def subprocess_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONUNBUFFERED"] = "1"
    return env


class BlockRun:
    """The background processes of one block; stopped (SIGINT) when the block ends."""

    def __init__(self, cwd: Path) -> None:
        self.cwd = cwd
        self.background: list[tuple[str, subprocess.Popen[str]]] = []
        self.pending: list[tuple[int, str, subprocess.Popen[str]]] = []

    def start(self, words: list[str]) -> None:
        words = server_words(words)
        proc = subprocess.Popen([str(BIN / "servobus"), *words[1:]], cwd=self.cwd,
                                env=subprocess_env(), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        self.background.append((shlex.join(words), proc))
        self.pending += [(port, shlex.join(words), proc) for port in
                         dict.fromkeys(ports_of(words))]

    def ready(self) -> None:
        """Wait until every server started so far answers on its ports (servers started one
        after the other start together: the next foreground command or the block's end
        waits for them)."""
        for port, command, proc in self.pending:
            wait_until(lambda port=port, proc=proc: answers(port) or proc.poll() is not None,
                       timeout=60, what=f"{command} listening on {port}")
            assert proc.poll() is None, self.failure(command, proc)
        self.pending.clear()

    def failure(self, command: str, proc: subprocess.Popen[str]) -> str:
        out, err = proc.communicate(timeout=10)
        return f"`{command}` ended with {proc.returncode}:\n{out[-2000:]}\n{err[-2000:]}"

    def stop(self) -> list[str]:
        """Stop every background process; the problems (one that died, or failed)."""
        problems: list[str] = []
        running = {id(proc) for _, proc in self.background if proc.poll() is None}
        for _, proc in self.background:  # every one at once: they shut down together
            if id(proc) in running:
                proc.send_signal(signal.SIGINT)
        for command, proc in reversed(self.background):
            if id(proc) not in running:
                if proc.returncode != 0:
                    problems.append(self.failure(command, proc))
                continue
            try:
                out, err = proc.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, err = proc.communicate(timeout=10)
            if proc.returncode not in (0, 130, -signal.SIGINT):
                problems.append(f"`{command}` ended with {proc.returncode} on Ctrl-C:\n"
                                f"{out[-2000:]}\n{err[-2000:]}")
        return problems


def run_command(command: str, run: BlockRun) -> Outcome | None:
    """One line of a shell block; None for a background process."""
    piped = ECHO_PIPE.match(command)
    if piped:  # echo 'TEXT' | servobus ...: in-process, TEXT on its stdin
        run.ready()
        saved, sys.stdin = sys.stdin, io.StringIO(piped[1] + "\n")
        try:
            return run_command(piped[2], run)
        finally:
            sys.stdin = saved
    if SHELL_SYNTAX.search(command.split("#", 1)[0]) and not command.lstrip().startswith(
            "servobus"):
        proc = subprocess.run(["bash", "-c", command], cwd=run.cwd, env=subprocess_env(),
                              capture_output=True, text=True, timeout=120)
        return Outcome(proc.returncode, proc.stdout, proc.stderr)
    words = words_of(command)
    env: dict[str, str] = {}
    while words and re.match(r"^[A-Z_]+=", words[0]):
        key, value = words.pop(0).split("=", 1)
        env[key] = value
    if not words:
        return Outcome(0, "", "")
    if is_background(words):
        run.start(words)
        return None
    run.ready()
    assert words[0] == "servobus", f"not a servobus command: {command}"
    return run_in_process(stream_words(words), env)


def run_shell_block(block: Block, cwd: Path) -> list[tuple[str, Outcome]]:
    text = with_free_ports("\n".join([*block.first, block.text]))
    run = BlockRun(cwd)
    results: list[tuple[str, Outcome]] = []
    previous = Path.cwd()
    os.chdir(cwd)
    try:
        for command in commands_of(text):
            outcome = run_command(command, run)
            if outcome is None:
                continue
            results.append((command, outcome))
            assert outcome.code == 0, (f"{block.id}: `{command}` exited {outcome.code}:\n"
                                       f"{outcome.stdout[-3000:]}\n{outcome.stderr[-3000:]}")
        run.ready()
    finally:
        os.chdir(previous)
        problems = run.stop()
    assert not problems, f"{block.id}: " + "\n".join(problems)
    return results


def run_python_block(block: Block, cwd: Path) -> str:
    """exec the block (top-level await allowed) in cwd; its stdout."""
    first_text = with_free_ports("\n".join([*block.first, block.text]))
    first = first_text.split("\n")[:len(block.first)]
    source = "\n".join(first_text.split("\n")[len(block.first):])
    run = BlockRun(cwd)
    out = io.StringIO()
    previous = Path.cwd()
    os.chdir(cwd)
    try:
        for command in first:
            run_command(command, run)
        run.ready()
        code = compile(source, block.id, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)
        namespace: dict[str, object] = {"__name__": "__docs__"}
        with contextlib.redirect_stdout(out):
            result = eval(code, namespace)
            if inspect.iscoroutine(result):
                asyncio.run(result)
    finally:
        os.chdir(previous)
        problems = run.stop()
    assert not problems, f"{block.id}: " + "\n".join(problems)
    return out.getvalue()


def machine_file_text() -> str:
    """docs/machine.md's example machine file, its links on in-process virtual drives."""
    text = (ROOT / "docs" / "machine.md").read_text(encoding="utf-8")
    toml = text.split("```toml\n", 1)[1].split("```", 1)[0]
    toml = toml.replace("dyn232+socket://127.0.0.1:4001", "sim://dyn232?ids=1,2&fast=1")
    return toml.replace("easycan+socketcand://127.0.0.1:29537", "sim://easycan?ids=1&fast=1")


def scratch(tmp: Path) -> Path:
    for name in ("cell.toml", "m.toml"):
        (tmp / name).write_text(machine_file_text(), encoding="utf-8")
    return tmp


def run_block(block: Block, tmp_path: Path) -> None:
    """One block as a test: skipped with its marker's reason, else run in a scratch folder."""
    if block.skip:
        pytest.skip(block.skip)
    if block.kind == "python":
        run_python_block(block, scratch(tmp_path))
    else:
        run_shell_block(block, scratch(tmp_path))
