"""The world model: what piga learns from video.

An object-centric encoder reads each object's coordinates from a frame (:mod:`.encoder`), a
velocity estimator turns the first frames' coordinates into a velocity (:mod:`.velocity`), a
differentiable physics engine with a few interpretable parameters steps the state forward
(:mod:`.physics`), and a coordinate-consistent decoder draws the state back into pixels
(:mod:`.decoder`). :mod:`.model` assembles the four into one ``PhysicsModel``. The baselines it is
compared with, without physical parameters, are :mod:`.video_lstm` (a black-box frame predictor) and
:mod:`.interaction` (an Interaction Network in place of the physics); :mod:`.variants` builds each by
name. :mod:`.mlp_decoder` is the black-box decoder of the paper's decoder ablation. Nothing here reads files, trains, or knows about agents.
"""
