"""The character's body: head frame, skinning, skeleton transfer, target preparation (paper Sec. 4.1)."""
