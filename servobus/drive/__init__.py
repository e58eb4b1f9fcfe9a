"""The drive model both sides share: parameter table, registers, units, profile math."""
