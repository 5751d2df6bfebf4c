"""Control: where the world model meets the agents.

This layer composes :mod:`piga`'s core with :mod:`agents`: it runs and scores episodes
(:mod:`.episodes`), farms batches of them out to worker processes (:mod:`.jobs`), reads goals given
as images (:mod:`.goal`), controls dm_control's pendulum (:mod:`.dmc`), and puts a diagnosis to
use in closed loop (:mod:`.corrected`, :mod:`.closed_loop`); :mod:`.registry` maps a run folder's kind to the agent it runs as. The core packages (world, data,
training, evaluation, diagnostics, io) never import it or :mod:`agents`.
"""
