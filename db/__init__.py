"""The pendant's storage: controllers, tool and base tables, history and calibration sessions."""
