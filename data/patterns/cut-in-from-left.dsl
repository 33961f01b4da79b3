# A vehicle in the lane to ego's left, then, within 4 s, in ego's lane ahead of ego (a cut-in from the left).
car = new Vehicle on Range(-6, -2.5) @ Range(-5, 30) relative to ego, facing Range(-30, 30) deg relative to ego
then within 4 s
car = new Vehicle on Range(-1.5, 1.5) @ Range(2, 30) relative to ego, facing Range(-30, 30) deg relative to ego
