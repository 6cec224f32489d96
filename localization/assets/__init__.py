"""Weights shipped with localization: masknet.pt, informed separation's mask network."""
