"""Every command block of docs/h*.md to docs/z*.md run on the virtual drives (tests/docs_rig.py).

docs/*.md is split over two files so that two workers share it (the suite runs
`--dist loadfile`).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from docs_rig import Block, all_blocks, params, run_block

BLOCKS = [b for b in all_blocks() if b.path.startswith("docs/") and b.path[5] > "g"]


@pytest.mark.parametrize("block", params(BLOCKS))
def test_docs_block_runs(block: Block, tmp_path: Path) -> None:
    run_block(block, tmp_path)
