# A vehicle in an intersection within 40 m of ego, facing anywhere.
car = new Vehicle on Range(-40, 40) @ Range(-40, 40) relative to ego, facing Range(0, 360) deg, in intersection
