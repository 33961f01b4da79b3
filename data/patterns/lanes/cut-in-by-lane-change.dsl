# A cut-in read by the lanes: a vehicle ahead of ego, in ego's lane, that has just changed lanes (its lane is on the
# chain of the left or right neighbour of its lane at a frame within 3 s before), so it came from beside ego.
car = new Vehicle on Range(-5, 5) @ Range(0, 40) relative to ego, in lane of ego, changing lanes
