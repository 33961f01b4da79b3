"""The recorded road, below the scene: map features and the rules a map obeys (`roadmap`), where a point is and the
lane facts of a pose (`lane_facts`), the rules that complete a source's lanes (`lane_geometry`) and the relations
between lanes the LANE part reads (`lane_relations`). It imports nothing of synth but `errors` and `geometry`:
a scene holds a road, a road knows no scene (docs/layout.md)."""
