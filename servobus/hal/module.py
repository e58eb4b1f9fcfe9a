"""Finding LinuxCNC's Python ``hal`` module (docs/linuxcnc.md, "How the hal module is found").

Debian's ``linuxcnc-uspace`` installs ``hal.py`` and ``_hal.cpython-311-*.so`` into the
system's ``dist-packages``, which a virtual environment does not see. Decision: the folder
is found at run time, never written down: ``SERVOBUS_HAL_PATH`` when set, else the folder
``dpkg -L linuxcnc-uspace`` lists ``hal.py`` in. It is appended to ``sys.path`` (after the
environment's own folders, so the environment's packages win).
"""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType

from servobus.errors import NotSupported

PATH_ENV = "SERVOBUS_HAL_PATH"
PACKAGE = "linuxcnc-uspace"


def hal_folder() -> Path | None:
    """The folder holding LinuxCNC's ``hal.py``: ``SERVOBUS_HAL_PATH``, else from dpkg."""
    named = os.environ.get(PATH_ENV)
    if named:
        return Path(named)
    dpkg = shutil.which("dpkg")
    if dpkg is None:
        return None
    try:
        listed = subprocess.run([dpkg, "-L", PACKAGE], capture_output=True, text=True,
                                timeout=30, check=False).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for line in listed.splitlines():
        path = Path(line.strip())
        if path.name == "hal.py" and path.parent.name in ("dist-packages", "site-packages"):
            return path.parent
    return None


def import_hal() -> ModuleType:
    """LinuxCNC's ``hal`` module, or NotSupported saying how to get it."""
    found = _linuxcnc_hal()
    if found is not None:
        return found
    folder = hal_folder()
    if folder is not None and str(folder) not in sys.path:
        sys.path.append(str(folder))
    sys.modules.pop("hal", None)  # not LinuxCNC's (a folder named hal is a namespace package)
    importlib.invalidate_caches()
    found = _linuxcnc_hal()
    if found is not None:
        return found
    where = f"{folder}" if folder is not None else "no folder found"
    raise NotSupported(
        f"LinuxCNC's Python hal module cannot be imported ({where}); install the Debian "
        f"package {PACKAGE} or name its folder in {PATH_ENV}")


def _linuxcnc_hal() -> ModuleType | None:
    """``import hal`` where it is a module, else None: a folder named ``hal`` on the path
    (a test folder, a checkout) imports as a namespace package, which has no origin."""
    try:
        module = importlib.import_module("hal")
    except ImportError:
        return None
    spec = module.__spec__
    return module if spec is not None and spec.origin not in (None, "namespace") else None
