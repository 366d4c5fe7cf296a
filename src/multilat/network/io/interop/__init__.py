"""Interchange with geodetic adjustment tools: GNU Gama (gama-local XML in, adjusted XML out), JAG3D (plain-text import files) and Star*Net (.dat). See docs/interop.md."""
