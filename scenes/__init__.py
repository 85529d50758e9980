"""MJCF scene templates and object assets, shipped as package data."""
