# A pedestrian on a crosswalk within 40 m ahead of ego (30 m to either side), facing anywhere.
ped = new Pedestrian on Range(-30, 30) @ Range(0, 40) relative to ego, facing Range(0, 360) deg, on crosswalk
