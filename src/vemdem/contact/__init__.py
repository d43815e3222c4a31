"""Contact between grains and walls: broad phase, master-to-master narrow phase, interface law,
friction and walls (paper section 2.2, docs/contact.md)."""
