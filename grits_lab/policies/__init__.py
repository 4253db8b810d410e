"""Scooping policies, one folder per method (diffusion, ...), each with its config and model."""
