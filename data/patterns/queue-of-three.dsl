# Three cars in a queue: each one ahead of the previous by 1 to 10 m, heading the same way within 20 degrees.
a = new Car on Range(-50, 50) @ Range(-50, 50), facing Range(0, 360) deg
b = new Car ahead of a by Range(1, 10), facing Range(-20, 20) deg relative to a
c = new Car ahead of b by Range(1, 10), facing Range(-20, 20) deg relative to b
