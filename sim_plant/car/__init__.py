"""The car: ``vehicle`` (single-track model, eqs. 14/16, exact ZOH discretisation) and
``scenario`` (operating point, events, driver model; built-ins and TOML files)."""
