"""The RWS face (ABB Robot Web Services 1.0) and the operations both controller faces call."""
