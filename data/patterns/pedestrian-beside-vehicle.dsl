# A pedestrian ahead of ego within 30 m, with a vehicle (any of the vehicle classes) right of them within 10 m.
ped = new Pedestrian ahead of ego by Range(0, 30), facing Range(0, 360) deg
car = new Vehicle right of ped by Range(0, 10), facing Range(0, 360) deg
