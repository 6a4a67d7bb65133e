"""Planning: grid path search (and, later, the frontier-tree planner)."""
