# A vehicle ahead of ego in ego's lane (its lane chain: docs/dsl.md, "Lanes"), within 30 m, heading ego's way.
lead = new Vehicle ahead of ego by Range(0, 30), facing Range(-30, 30) deg relative to ego, in lane of ego
