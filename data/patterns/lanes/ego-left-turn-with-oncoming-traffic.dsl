# Ego turns left at an intersection with oncoming traffic: a vehicle ahead of ego faces it from the other way
# (queued or moving), then, within 6 s, ego is in an intersection turning left (its heading in the world 30 degrees
# or more counter-clockwise within 3 s) with that vehicle still within 60 m.
car = new Vehicle on Range(-40, 40) @ Range(0, 60) relative to ego, facing Range(135, 225) deg relative to ego
then within 6 s
car = new Vehicle within Range(0, 60) of ego
ego in intersection, turning left
