"""Readers and writers: the only part of lidar2city that touches files."""

__all__: list[str] = []
