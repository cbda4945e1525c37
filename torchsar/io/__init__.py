"""Readers of SAR data files."""

from torchsar.io.gotcha import GotchaPass, gotcha_files, read_gotcha

__all__ = ["GotchaPass", "gotcha_files", "read_gotcha"]
