"""Sections of the pages other than docs/odometry.md's drive tables."""

SECTIONS = []
