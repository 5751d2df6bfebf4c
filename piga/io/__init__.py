"""Plumbing shared by every command: atomic writes, resource checks, worker signals, and run folders.

:mod:`.atomic` writes files so that a crash never leaves a half-written one, :mod:`.resources`
checks memory and disk before a command allocates or writes, :mod:`.worker_signals` makes worker
processes stop cleanly, and :mod:`.runs` reads a training run's folder (its model and what it says
about itself).
"""
