"""Every command block of README.md runs against the virtual drives (tests/docs_rig.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from docs_rig import Block, all_blocks, params, run_block

BLOCKS = all_blocks(("README.md",))


@pytest.mark.parametrize("block", params(BLOCKS))
def test_readme_block_runs(block: Block, tmp_path: Path) -> None:
    run_block(block, tmp_path)
