"""The regression: named terms, the term library, normal equations per block (BlockGram),
their sources per recording, and the sparse optimizers."""
