"""Variants of a recorded scene: sampling them from its program (sample, for `r2s sample` and `r2s render
--samples`) and drawing a scene, its program's references and its variants from above (render)."""
