"""Variants of a scene, drawn from its program: the sampler's chain (`gibbs`), what is drawn for a program
(`parameters`), the collision rule (`collision_rule`, `overlap`) and the road variants are placed on, a scene's
road with the lane facts of every pose tried (`scene_road`)."""
