"""Identification layer: the seed paper's FSR bench, DMA and block-model identification, simulated."""
