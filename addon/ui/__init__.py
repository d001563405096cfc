"""Properties, panels and operators."""
