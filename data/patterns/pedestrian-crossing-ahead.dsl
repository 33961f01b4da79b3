# A pedestrian ahead of ego on its left, then, within 10 s, ahead of ego on its right (crossing left to right).
ped = new Pedestrian on Range(-12, -0.5) @ Range(0, 25) relative to ego, facing Range(0, 360) deg
then within 10 s
ped = new Pedestrian on Range(0.5, 12) @ Range(0, 25) relative to ego, facing Range(0, 360) deg
