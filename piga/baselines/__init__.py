"""Baselines trained and evaluated beside piga: the PlaNet-style world model (:mod:`piga.baselines.planet`)
and stable-baselines3 DDPG (:mod:`piga.baselines.ddpg`). Their run folders say what they are
(:mod:`piga.baselines.kinds`), so that ``piga-control --model RUN_DIR`` evaluates any of them."""
