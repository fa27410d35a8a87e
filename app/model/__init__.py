"""The editing model, Qt-free: what the user edits and how it is opened, saved and rendered."""
