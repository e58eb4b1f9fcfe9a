"""LinuxCNC's ``halrun`` in tests (docs/linuxcnc.md, "Testing"): a HAL session a test
starts from a HAL file, reads and sets pins in with ``halcmd``, and ends; tests skip in one
line where the Debian package ``linuxcnc-uspace`` is missing.

As root, ``rtapi_app`` refuses to start without a fallback user: ``RTAPI_UID`` names one
(nobody) and ``RTAPI_FIFO_PATH`` its socket, in a folder that user can write (the socket's
path itself, not a folder). HAL's shared memory is one per host: one session at a time
(the tests that use it sit in one file, which runs on one worker).
"""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

HALRUN = shutil.which("halrun")
HALCMD = shutil.which("halcmd")
needs_halrun = pytest.mark.skipif(HALRUN is None or HALCMD is None,
                                  reason="LinuxCNC's halrun is missing (Debian linuxcnc-uspace)")


LINUXCNC = shutil.which("linuxcnc")
SCRIPT = shutil.which("script")
needs_linuxcnc = pytest.mark.skipif(LINUXCNC is None or SCRIPT is None,
                                    reason="LinuxCNC (linuxcnc-uspace) or script is missing")


def hal_env(fifo: Path) -> dict[str, str]:
    """The environment of halrun, halcmd and linuxcnc (module docstring); ``fifo`` is a
    folder the fallback user can reach and write (pytest's tmp_path is not: its parent is
    root's alone)."""
    env = dict(os.environ)
    fifo.chmod(0o777)
    env["RTAPI_FIFO_PATH"] = str(fifo / "rtapi")
    if os.geteuid() == 0:
        env["RTAPI_UID"] = str(pwd.getpwnam("nobody").pw_uid)
    return env


def run_linuxcnc(ini: Path, *, timeout: float = 150.0) -> str:
    """``linuxcnc INI`` under a pseudo-terminal (without a tty its launcher opens a terminal
    window), servobus on PATH; its output (it ends when the INI's display exits)."""
    assert SCRIPT is not None
    with tempfile.TemporaryDirectory(prefix="servobus-rtapi-") as fifo:
        env = hal_env(Path(fifo))
        env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
        done = subprocess.run([SCRIPT, "-qec", f"linuxcnc {ini.name}", "/dev/null"],
                              cwd=ini.parent, env=env, capture_output=True, text=True,
                              timeout=timeout, check=False)
    return done.stdout + done.stderr


class HalSession:
    """``halrun -I -f FILE`` kept open; its output (and the components') in a log file."""

    def __init__(self, hal_file: Path) -> None:
        assert HALRUN is not None and HALCMD is not None
        self.folder = hal_file.parent
        self._fifo = tempfile.TemporaryDirectory(prefix="servobus-rtapi-")
        self.env = hal_env(Path(self._fifo.name))
        self.log = self.folder / "halrun.log"
        with self.log.open("w") as log:
            self.proc = subprocess.Popen([HALRUN, "-I", "-f", hal_file.name], cwd=self.folder,
                                         env=self.env, stdin=subprocess.PIPE, stdout=log,
                                         stderr=subprocess.STDOUT, text=True)

    def halcmd(self, *args: str) -> str:
        assert HALCMD is not None
        done = subprocess.run([HALCMD, "-s", *args], cwd=self.folder, env=self.env,
                              capture_output=True, text=True, timeout=30, check=False)
        assert done.returncode == 0, f"halcmd {' '.join(args)}: {done.stderr}{self.output()}"
        return done.stdout

    def loadusr(self, *args: str) -> None:
        """``halcmd loadusr ARGS``, the component's output appended to the log (halcmd's
        pipes would stay open as long as the component runs)."""
        assert HALCMD is not None
        with self.log.open("a") as log:
            done = subprocess.run([HALCMD, "loadusr", *args], cwd=self.folder, env=self.env,
                                  stdout=log, stderr=subprocess.STDOUT, timeout=120,
                                  check=False)
        assert done.returncode == 0, f"halcmd loadusr {' '.join(args)}{self.output()}"

    def user_pid(self, name: str) -> int:
        """The process id of the userspace component ``name`` (``halcmd show comp``)."""
        for line in self.halcmd("show", "comp").splitlines():
            parts = line.split()
            if len(parts) >= 4 and parts[1] == "User" and parts[2] == name:
                return int(parts[3])
        raise AssertionError(f"no userspace component {name}{self.output()}")

    def pins(self, prefix: str) -> dict[str, str]:
        """``halcmd show pin PREFIX``: name -> value as halcmd prints it."""
        found = {}
        for line in self.halcmd("show", "pin", prefix).splitlines():
            parts = line.split()
            if len(parts) >= 5:
                found[parts[4]] = parts[3]
        return found

    def output(self) -> str:
        return "\n--- halrun log ---\n" + self.log.read_text(errors="replace")

    def close(self) -> None:
        """``exit`` (halrun unloads every component: SIGTERM to ``loadusr`` ones), else
        halrun -U."""
        assert HALRUN is not None
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write("exit\n")
                self.proc.stdin.close()
                self.proc.wait(timeout=30)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()
        if self.proc.returncode != 0:
            subprocess.run([HALRUN, "-U"], env=self.env, capture_output=True, timeout=60,
                           check=False)
        self._fifo.cleanup()
