"""Every command block of README.md runs against the virtual drives (tests/docs_rig.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from docs_rig import Block, all_blocks, params, run_python_block, run_shell_block, scratch

BLOCKS = all_blocks(("README.md",))


@pytest.mark.parametrize("block", params(BLOCKS))
def test_readme_block_runs(block: Block, tmp_path: Path) -> None:
    if block.skip:
        pytest.skip(block.skip)
    if block.kind == "python":
        run_python_block(block, scratch(tmp_path))
    else:
        run_shell_block(block, scratch(tmp_path))
