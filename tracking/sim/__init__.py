"""Simulator: renders what the paper's cameras would see, with exact ground truth (see README.md here)."""
