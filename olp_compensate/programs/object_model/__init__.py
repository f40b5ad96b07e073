"""The named-target object model shared by RAPID and V+/AS (targets declared by name, used by
motion instructions: :mod:`..targets`) and its compensation: modules, tasks, configurations."""
