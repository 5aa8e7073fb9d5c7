"""The align stage: symmetric InfoNCE projection heads (paper eq. 1), retrieval, grid cells."""
