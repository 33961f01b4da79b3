# A pedestrian within 10 m of ego, within delta1 of ego's heading, facing anywhere.
ped = new Pedestrian ahead of ego by Range(0, 10), facing Range(0, 360) deg
