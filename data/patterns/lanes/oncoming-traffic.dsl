# A vehicle in ego's oncoming lane within 60 m ahead or behind, facing against ego's way.
car = new Vehicle on Range(-20, 20) @ Range(-60, 60) relative to ego, facing Range(150, 210) deg relative to ego, in oncoming lane of ego
