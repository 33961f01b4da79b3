# A pedestrian within 10 m of ego, in any direction and facing any way (docs/dsl.md#patterns: a left-out heading is any)
ped = new Pedestrian within Range(0, 10) of ego
