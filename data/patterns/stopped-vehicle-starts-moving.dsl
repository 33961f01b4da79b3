# A vehicle near ego standing still for at least 2 s, then, within 3 s, moving at 1 m/s or more.
car = new Vehicle on Range(-30, 30) @ Range(-30, 30) relative to ego, facing Range(0, 360) deg, stationary
for at least 2 s
then within 3 s
car = new Vehicle on Range(-30, 30) @ Range(-30, 30) relative to ego, facing Range(0, 360) deg, moving Range(1, 100) m/s
