"""Programs over a window of consecutive frames: one program for the window and how windows tile a scene
(`program`), and the one road the window's Scenic text stands on (`road`)."""
