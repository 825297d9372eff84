"""``artgs check``: a robot opens every part in PyBullet along the estimated joints."""
