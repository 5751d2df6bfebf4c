"""Data: piga's one HDF5 schema for videos with actions, and every way into it.

:mod:`.schema` defines the file format and reads and writes it; :mod:`.collect` and
:mod:`.collect_scenes` record the simulated systems into it, :mod:`.importer` brings in a user's
own video with a CSV of actions, :mod:`.scene` converts pictures as the environments convert
their renders, and :mod:`.windows` cuts a file into training items. Nothing here imports torch
models or agents.
"""
