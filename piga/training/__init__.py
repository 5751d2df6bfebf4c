"""Training: fitting the world model to a data file, frames and actions only.

:mod:`.train` holds the recipes (typed ``TrainConfig`` values), plans a run from the data, trains
with warm-up, curriculum and checkpoints, and resumes exactly; :mod:`.convergence` judges from the
run's own trajectory whether the parameters were identified; :mod:`.report` writes what a run
leaves behind (metrics.json and its figures). Training never reads ``/states``.
"""
