"""Example scenes, shipped as the built-in scenes of `vibinverse demo` (package data)."""
