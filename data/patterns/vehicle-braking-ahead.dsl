# A vehicle ahead of ego in ego's lane, heading ego's way, braking (its speed down by 1 m/s or more within 1 s).
car = new Vehicle on Range(-1.5, 1.5) @ Range(2, 40) relative to ego, facing Range(-20, 20) deg relative to ego, braking
