# A moving vehicle within 40 m of ego, in an intersection, turning left (its heading in the world 30 degrees or
# more counter-clockwise within 3 s).
car = new Vehicle on Range(-40, 40) @ Range(-40, 40) relative to ego, moving Range(1, 40) m/s, in intersection, turning left
