"""Readers and writers: multilat's CSV files, large-file readers, and :mod:`.interop` (GNU Gama,
JAG3D, Star*Net). Built on :mod:`multilat.network.model.distance` only.
"""
