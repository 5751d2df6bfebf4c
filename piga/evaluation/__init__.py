"""Evaluation: how good a trained model is, in numbers and in pictures.

:mod:`.evaluate` scores a model on held-out sequences (parameters, frames, states), :mod:`.plots`
draws the figures a person looks at, and :mod:`.video` writes control episodes as videos (the real
frame beside the model's belief and plan); :mod:`.episodes` holds control episodes' typed results and their tables.
"""
