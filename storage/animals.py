"""Animal records: create, list, read, update, delete."""

from __future__ import annotations

from sqlalchemy import func
from sqlmodel import Session, select

from .errors import ConflictError, NotFoundError
from .models import Animal, AnimalCreate, AnimalUpdate, MeasuringSession, utcnow


def create_animal(session: Session, data: AnimalCreate) -> Animal:
    """Insert an animal; ConflictError when the tag is taken."""
    _check_tag_free(session, data.tag)
    animal = Animal.model_validate(data)
    session.add(animal)
    session.flush()
    return animal


def get_animal(session: Session, animal_id: int) -> Animal:
    animal = session.get(Animal, animal_id)
    if animal is None:
        raise NotFoundError("animal", animal_id)
    return animal


def list_animals(session: Session, species: str | None = None, status: str | None = None,
                 tag: str | None = None, offset: int = 0, limit: int = 100) -> list[Animal]:
    """Animals ordered by tag; filters compare case-insensitively, ``tag`` matches a substring."""
    query = select(Animal)
    if species:
        query = query.where(func.lower(Animal.species) == species.lower())
    if status:
        query = query.where(func.lower(Animal.status) == status.lower())
    if tag:
        query = query.where(func.lower(Animal.tag).contains(tag.lower()))
    return list(session.exec(query.order_by(Animal.tag).offset(offset).limit(limit)))


def update_animal(session: Session, animal_id: int, data: AnimalUpdate) -> Animal:
    """Apply the fields present in ``data``; ConflictError when the new tag is taken."""
    animal = get_animal(session, animal_id)
    changes = data.model_dump(exclude_unset=True)
    if changes.get("tag") is not None:
        changes["tag"] = changes["tag"].strip()
        if changes["tag"] != animal.tag:
            _check_tag_free(session, changes["tag"])
    for key, value in changes.items():
        setattr(animal, key, value)
    animal.updated_at = utcnow()
    session.add(animal)
    session.flush()
    return animal


def delete_animal(session: Session, animal_id: int) -> None:
    """Delete an animal that has no sessions; its measurements would otherwise be lost."""
    animal = get_animal(session, animal_id)
    count = session.exec(select(func.count()).where(MeasuringSession.animal_id == animal_id)).one()
    if count:
        raise ConflictError(f"animal {animal.tag!r} has {count} session(s) with measurements; "
                            "set its status (e.g. 'sold') instead of deleting it")
    session.delete(animal)
    session.flush()


def _check_tag_free(session: Session, tag: str) -> None:
    if session.exec(select(Animal.id).where(Animal.tag == tag)).first() is not None:
        raise ConflictError(f"animal tag {tag!r} already exists")
