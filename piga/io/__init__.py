"""Plumbing shared by every command: atomic writes, resource checks, worker processes, and run folders.

:mod:`.atomic` writes files so that a crash never leaves a half-written one, :mod:`.resources`
checks memory and disk before a command allocates or writes, :mod:`.worker_signals` makes worker
processes stop cleanly, :mod:`.pool` runs jobs in worker processes (or, through :mod:`.ray_backend`, on a
Ray cluster) and resumes them from their records, :mod:`.choices` checks a config's ``Literal`` fields,
:mod:`.checkpoint` says what kind a run folder is and writes and reads its one checkpoint, :mod:`.runs`
reads a training run's folder (its model and what it says about itself), :mod:`.device` resolves the
``--device`` choice to a torch device, and :mod:`.progress` clears a progress bar that an error ends.
"""
