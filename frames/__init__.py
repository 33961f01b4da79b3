"""The frames format, between storage and the extractors: the one frames schema (`schema`), a frame's rows to a
Scene and back (`rows`), frames datasets read in row groups and their streaming check (`dataset`), written by
`writer`, the maps beside the frames (`maps`), a frame's content hash (`frame_hash`) and the stable entity ids
every source gives (`naming`). It may import synth and storage; extractors and pipeline import it
(docs/layout.md)."""
