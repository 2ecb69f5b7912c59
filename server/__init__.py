"""The pendant service: REST menus over the emulated controllers, the DB and the solvers."""
