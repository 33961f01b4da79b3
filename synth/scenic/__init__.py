"""Scenic text for a program (`emit`) and the recorded road in it (`road`). Its modules import the Scenic library
absolutely (`import scenic`), which this package, always named `synth.scenic`, never shadows."""
