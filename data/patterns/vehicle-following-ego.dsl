# A moving vehicle behind ego in ego's lane, heading ego's way, for at least 3 s.
car = new Vehicle on Range(-1.5, 1.5) @ Range(-30, -3) relative to ego, facing Range(-20, 20) deg relative to ego, moving Range(1, 60) m/s
for at least 3 s
